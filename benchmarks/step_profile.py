"""Where a training step's time goes: per variant, the median step time, peak memory, samples per ray, and (with
``--profile``) the kernels that take the most device time, on one scene built once.

    python benchmarks/step_profile.py --set device=cuda +experiment=paper_phantom5 data.sensing=ideal \\
        --variants "" "encoder.kernel=torch" "mask=none sampler=uniform" --profile

Each variant builds its solver and masks from the same scene (``--set`` plus the variant's overrides; overrides
that change the data are not allowed in a variant), takes ``--warmup`` steps, then times ``--steps`` steps, the
device synchronised around each. Writes ``step_profile.json`` and ``step_profile.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from nerif.app import resolve_device, retain_freed_memory
from nerif.threads import resolve_threads
from nerif.configs import compose, group
from nerif.data import DATASETS
from nerif.masks import MASKS
from nerif.solvers import SOLVERS

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402


def synchronize(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def time_steps(solver, n: int, device: torch.device) -> list[float]:
    """Seconds of each of ``n`` training steps (the iteration counter advanced as ``fit`` does)."""
    out = []
    for _ in range(n):
        synchronize(device)
        t = time.perf_counter()
        solver.step()
        synchronize(device)
        out.append(time.perf_counter() - t)
        solver.iteration += 1
    return out


def profile_steps(solver, n: int, device: torch.device, rows: int = 12) -> str:
    """torch.profiler's table of the operators with the most device (else CPU) time over ``n`` steps."""
    from torch.profiler import ProfilerActivity, profile

    acts = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with profile(activities=acts) as prof:
        time_steps(solver, n, device)
    key = "self_cuda_time_total" if device.type == "cuda" else "self_cpu_time_total"
    return prof.key_averages().table(sort_by=key, row_limit=rows, max_name_column_width=50)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", nargs="*", default=[], help="overrides for the scene and every variant")
    ap.add_argument("--variants", nargs="+", default=[""], help="overrides per variant ('' = --set alone)")
    ap.add_argument("--warmup", type=int, default=30)
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--profile", action="store_true", help="also print the profiler's table for 5 steps")
    ap.add_argument("--out", default="benchmarks/results/step_profile")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    base = compose(args.set)
    device = resolve_device(base.device)
    torch.set_num_threads(resolve_threads(base.threads))  # as python -m nerif
    retain_freed_memory()
    t0 = time.perf_counter()
    scene = DATASETS.build(group(base, "data"), device=str(device))
    print(f"scene: {len(scene.dirs)} rays, built in {time.perf_counter() - t0:.1f} s", flush=True)
    rows = {}
    for v in args.variants:
        cfg = compose(args.set + v.split())
        if group(cfg, "data") != group(base, "data"):
            raise SystemExit(f"variant '{v}' changes the data: give data settings in --set")
        torch.manual_seed(cfg.seed)
        solver = SOLVERS.build(group(cfg, "solver"))
        solver.setup(scene, MASKS.build(group(cfg, "mask"), scene=scene))
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(device)
        time_steps(solver, args.warmup, device)
        steps = np.asarray(time_steps(solver, args.steps, device)) * 1e3
        name = v or "(as set)"
        rows[name] = {"ms_per_iteration": float(np.median(steps)), "ms_p10": float(np.percentile(steps, 10)),
                      "ms_p90": float(np.percentile(steps, 90)),
                      "peak_memory_gib": torch.cuda.max_memory_allocated(device) / 2**30 if device.type == "cuda" else None,
                      "samples_per_ray": solver.counts.samples_seen / max(solver.counts.rays_seen, 1)}
        print(f"{name}: {rows[name]['ms_per_iteration']:.2f} ms/it (p10 {rows[name]['ms_p10']:.2f}, "
              f"p90 {rows[name]['ms_p90']:.2f})", flush=True)
        if args.profile:
            print(profile_steps(solver, 5, device), flush=True)
        del solver
    lines = [f"Step times on `{' '.join(args.set)}`; {torch.cuda.get_device_name(device) if device.type == 'cuda' else platform.processor() or 'CPU'}, "
             f"torch {torch.__version__}, {args.steps} steps after {args.warmup}", "",
             "| variant | ms/it (median) | p10 | p90 | peak memory [GiB] | samples/ray |", "|---|---|---|---|---|---|"]
    for name, r in rows.items():
        mem = "-" if r["peak_memory_gib"] is None else f"{r['peak_memory_gib']:.2f}"
        lines.append(f"| {name} | {r['ms_per_iteration']:.2f} | {r['ms_p10']:.2f} | {r['ms_p90']:.2f} | {mem} | "
                     f"{r['samples_per_ray']:.1f} |")
    write_report(out, "step_profile", {"settings": args.set, "device": str(device), "variants": rows},
                 "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
