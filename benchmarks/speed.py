"""Time to accuracy: for each variant, ms/iteration, samples/s, field evaluations/s, the time to reach 25 / 20 / 15 K,
the final RMSE and the peak memory, side by side in one process.

    python benchmarks/speed.py                                   # default scene, CPU: the variants below
    python benchmarks/speed.py --set device=cuda +experiment=paper_phantom5 train.eval_every=500

Every variant runs through ``nerif.app.run`` (:func:`benchmarks.ablation.run_cells`) with evaluations every
``train.eval_every=100`` iterations, so the time to a given error is read at that resolution (training time
only: evaluations are not counted). Field evaluations per sample: 7 for ``grad=discrete`` (the value and its 6
central-difference neighbours), 1 for ``auto`` (plus its double backward). Writes ``speed.json`` and ``speed.md``
under ``--out``.
"""
from __future__ import annotations

import argparse
import resource
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import header, run_cells, time_to, write_report  # noqa: E402


VARIANTS = {
    "default (mixed views, discrete, 3d, occupancy)": "",
    "one view per batch (paper)": "train.views_per_batch=1",
    "grad=auto": "grad=auto",
    "mask=3d sampler=uniform": "sampler=uniform",
}
TARGETS_K = (25.0, 20.0, 15.0)
EVALS_PER_SAMPLE = {"discrete": 7, "auto": 1, "hybrid": 7}


def table(rows: dict[str, dict]) -> str:
    heads = ["variant", "ms/it", "samples/s", "field evals/s"] + [f"to {t:g} K [s]" for t in TARGETS_K] + \
            ["final T RMSE [K]", "peak memory [GiB]"]
    lines = ["| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for name, r in rows.items():
        reach = ["-" if r[f"time_to_{t:g}K_s"] is None else f"{r[f'time_to_{t:g}K_s']:.0f}" for t in TARGETS_K]
        lines.append(f"| {name} | {r['ms_per_iteration']:.1f} | {r['samples_per_second']:.3g} | "
                     f"{r['field_evaluations_per_second']:.3g} | " + " | ".join(reach) +
                     f" | {r['temperature_rmse_K']:.1f} | {r['peak_memory_gib']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every variant")
    ap.add_argument("--out", default="benchmarks/results/speed")
    ap.add_argument("--resume", action="store_true", help="read back the runs an interrupted benchmark finished")
    args = ap.parse_args(argv)
    out = Path(args.out)
    settings = ["train.eval_every=100"] + args.set
    table_rows = run_cells([VARIANTS[v] or "seed=0" for v in args.variants], settings, out, resume=args.resume)
    rows = {}
    for name, r in zip(args.variants, table_rows):
        per_sample = EVALS_PER_SAMPLE.get(r.get("grad", "discrete"), 7)
        rows[name] = {**{k: r.get(k) for k in ("ms_per_iteration", "samples_per_second", "temperature_rmse_K",
                                               "wall_time_s", "device")},
                      "field_evaluations_per_second": per_sample * r["samples_per_second"],
                      "peak_memory_gib": r.get("gpu_peak_memory_gib",
                                               resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20),
                      **{f"time_to_{t:g}K_s": time_to(r["history"], t) for t in TARGETS_K},
                      "history": r["history"]}
    text = f"Time to accuracy, {header(settings, table_rows)}\n\n{table(rows)}"
    text += ("\nPeak memory on the CPU is the process's maximum resident set so far (the largest variant up to "
             "that row); on a GPU, the run's own peak allocation.\n")
    write_report(out, "speed", {"settings": settings, "rows": rows}, text)
    return rows


if __name__ == "__main__":
    main()
