"""Time to accuracy: for each variant, ms/iteration, samples/s, field evaluations/s, the time to reach 25 / 20 / 15 K,
the final RMSE and the peak memory, side by side in one process.

    python benchmarks/speed.py                                   # default scene, CPU: the variants below
    python benchmarks/speed.py --set device=cuda +experiment=paper_phantom5 train.eval_every=500
    python benchmarks/speed.py --against d903f8d                 # also each variant from that commit's code

``--against`` takes git refs of this repository (checked out into temporary worktrees) or folders holding another
checkout; each runs the same variants with its own code and configs, as ``python -m nerif`` in a subprocess,
right after this checkout's, so that speed-ups are ratios measured side by side on the same machine and load.

Every variant runs through ``nerif.app.run`` (:func:`benchmarks.ablation.run_cells`) with evaluations every
``train.eval_every=100`` iterations, so the time to a given error is read at that resolution (training time
only: evaluations are not counted). Field evaluations per sample: 6 for ``grad=discrete`` (the central-difference
neighbours; the value itself is never needed; 4 with ``grad.stencil=across`` on perpendicular-only data),
1 for ``auto`` (plus its double backward), 7 for ``hybrid``.
Writes ``speed.json`` and ``speed.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
from contextlib import ExitStack
from pathlib import Path
from typing import Optional

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import header, run_cells, time_to, write_report  # noqa: E402


VARIANTS = {
    "default (mixed views, discrete, 3d, occupancy)": "",
    "one view per batch (paper)": "train.views_per_batch=1",
    "grad=auto": "grad=auto",
    "mask=3d sampler=uniform": "sampler=uniform",
    "perpendicular-only data": "data.sensing=perpendicular",
    "perpendicular-only data, grad.stencil=across": "data.sensing=perpendicular grad.stencil=across",
}
TARGETS_K = (25.0, 20.0, 15.0)
EVALS_PER_SAMPLE = {"discrete": 6, "auto": 1, "hybrid": 7}


def table(rows: dict[str, dict]) -> str:
    heads = ["variant", "ms/it", "samples/s", "field evals/s"] + [f"to {t:g} K [s]" for t in TARGETS_K] + \
            ["final T RMSE [K]", "peak memory [GiB]"]
    lines = ["| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for name, r in rows.items():
        reach = ["-" if r[f"time_to_{t:g}K_s"] is None else f"{r[f'time_to_{t:g}K_s']:.0f}" for t in TARGETS_K]
        lines.append(f"| {name} | {r['ms_per_iteration']:.1f} | {r['samples_per_second']:.3g} | "
                     f"{r['field_evaluations_per_second']:.3g} | " + " | ".join(reach) +
                     f" | {r['temperature_rmse_K']:.1f} | " +
                     ("-" if r["peak_memory_gib"] is None else f"{r['peak_memory_gib']:.2f}") + " |")
    return "\n".join(lines) + "\n"


def ratios(rows: dict[str, dict], variants: list[str], refs: list[str]) -> str:
    """This checkout's times to each target and final RMSE as ratios of each other checkout's, per variant."""
    heads = ["variant", "against"] + [f"time to {t:g} K" for t in TARGETS_K] + ["ms/it", "final T RMSE"]
    lines = ["| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for name in variants:
        for ref in refs:
            if f"{name} @ {ref}" not in rows:
                continue
            a, b = rows[name], rows[f"{name} @ {ref}"]
            cells = []
            for t in TARGETS_K:
                ta, tb = a[f"time_to_{t:g}K_s"], b[f"time_to_{t:g}K_s"]
                cells.append("-" if ta is None or tb is None else f"{ta / tb:.2f}x")
            cells += [f"{a['ms_per_iteration'] / b['ms_per_iteration']:.2f}x",
                      f"{a['temperature_rmse_K'] / b['temperature_rmse_K']:.2f}x"]
            lines.append(f"| {name} | {ref} | " + " | ".join(cells) + " |")
    return "This checkout against the others (ratio: this / other; below 1 is better):\n\n" + "\n".join(lines) + "\n"


def checkout(ref: str, stack: ExitStack) -> Path:
    """A folder holding the code of ``ref``: the folder itself if it is one, else a temporary git worktree of this
    repository at that ref (removed when ``stack`` closes)."""
    if Path(ref).is_dir():
        return Path(ref).resolve()
    repo = Path(__file__).resolve().parents[1]
    folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="nerif-speed-"))) / "tree"
    done = subprocess.run(["git", "-C", str(repo), "worktree", "add", "--detach", str(folder), ref],
                          capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"--against {ref}: neither a folder nor a git ref of {repo} ({done.stderr.strip()})")
    stack.callback(subprocess.run, ["git", "-C", str(repo), "worktree", "remove", "--force", str(folder)],
                   capture_output=True)
    return folder


def run_elsewhere(tree: Path, cell: str, settings: list[str], folder: Path, resume: bool) -> Optional[dict]:
    """One cell run by the code and configs of another checkout (``python -m nerif`` there, in a subprocess
    with the same threads); its ``metrics.json``, or None (with one line saying why) when that checkout cannot run
    it (an older one may lack the cell's settings): the other rows are still reported."""
    metrics = folder / "metrics.json"
    if not (resume and metrics.is_file()):
        env = {**os.environ, "PYTHONPATH": str(tree)}
        cmd = [sys.executable, "-m", "nerif", f"hydra.run.dir={folder.resolve()}", "train.progress=false",
               *settings, *cell.split()]
        done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
        if done.returncode or not metrics.is_file():
            lines = [line.strip() for line in done.stderr.splitlines() if line.strip()] or ["no metrics.json"]
            why = lines[0] if len(lines) == 1 else f"{lines[0]} ... {lines[-1]}"  # Hydra's sentence, or the error
            print(f"{tree}: {' '.join(cmd[2:])} failed: {why}", flush=True)
            return None
        m = json.loads(metrics.read_text())
        m.setdefault("peak_memory_gib", resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20)  # so far
        return m
    return json.loads(metrics.read_text())  # read back: its memory was not measured here


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every variant")
    ap.add_argument("--out", default="benchmarks/results/speed")
    ap.add_argument("--resume", action="store_true", help="read back the runs an interrupted benchmark finished")
    ap.add_argument("--against", nargs="*", default=[],
                    help="git refs or folders of other checkouts whose code runs the same variants")
    args = ap.parse_args(argv)
    out = Path(args.out)
    settings = ["train.eval_every=100"] + args.set
    cells = [VARIANTS[v] or "seed=0" for v in args.variants]
    names = list(args.variants)
    failed = []  # cells another checkout could not run
    with ExitStack() as stack:
        trees = {ref: checkout(ref, stack) for ref in args.against}  # a bad ref fails before any run
        table_rows = run_cells(cells, settings, out, resume=args.resume)
        for ref, tree in trees.items():
            for i, (name, cell) in enumerate(zip(args.variants, cells)):
                folder = out / f"against_{Path(ref).name or ref}_{i}"
                m = run_elsewhere(tree, cell, settings, folder, args.resume)
                if m is None:
                    failed.append(f"{name} @ {ref}")
                    continue
                table_rows.append({**m, "config": cell})
                names.append(f"{name} @ {ref}")
                print(f"{name} @ {ref}: {m['temperature_rmse_K']:.1f} K, {m['ms_per_iteration']:.1f} ms/it", flush=True)
    rows = {}
    for name, r in zip(names, table_rows):
        # the solver reports it; a checkout older than that does not, and ran the axis stencil
        per_sample = r.get("field_evaluations_per_sample") or EVALS_PER_SAMPLE[r.get("grad", "discrete")]
        rows[name] = {**{k: r.get(k) for k in ("ms_per_iteration", "samples_per_second", "temperature_rmse_K",
                                               "wall_time_s", "device")},
                      "field_evaluations_per_second": per_sample * r["samples_per_second"],
                      "peak_memory_gib": r.get("gpu_peak_memory_gib", r.get("peak_memory_gib")),
                      **{f"time_to_{t:g}K_s": time_to(r["history"], t) for t in TARGETS_K},
                      "history": r["history"]}
    text = f"Time to accuracy, {header(settings, table_rows)}\n\n{table(rows)}"
    if args.against:
        text += "\n" + ratios(rows, args.variants, args.against)
    if failed:
        text += "\nNot run (that checkout's run failed, the reason printed above): " + ", ".join(failed) + ".\n"
    text += ("\nPeak memory: on a GPU, the run's own peak allocation; on the CPU, for another checkout's rows the "
             "largest resident set of its subprocesses so far ('-' when read back by --resume), and this checkout's "
             "variants share one process, " + ("whose memory a --resume run does not measure.\n" if args.resume else
                                               "whose peak resident set was "
                                               f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20:.2f} GiB.\n"))
    write_report(out, "speed", {"settings": settings, "rows": rows, "not_run": failed}, text)
    return rows


if __name__ == "__main__":
    main()
