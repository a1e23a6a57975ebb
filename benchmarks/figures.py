"""The time to draw each of a run's pictures, this checkout beside ``--against`` checkouts, side by side in one run.

    python benchmarks/figures.py --against 4737a23 --out /tmp/figures

Each figure of :data:`FIGURES`, drawn from made-up inputs smaller than a shared capture (a 240 x 320 px view on a
ray grid 8 px apart, a 30 x 50 x 30 probe box of 2 mm voxels, 9 views) and written as PNG bytes as a run writes it,
``--repeats`` times in a fresh Python per checkout (the checkouts alternate, so that a change in the machine's load
falls on both; the first drawing of a process, which loads fonts, is not timed). Prints the median seconds per
figure and writes ``figures.json`` and ``figures.md`` under ``--out``. Times are this machine's: compare the columns
of one run. The figures of two checkouts need not be the same images (a layout is what a change may move): look at
them.
"""
from __future__ import annotations

import argparse
import sys
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from patterns import alternating_runs  # noqa: E402
from speed import checkout  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# name: the call drawing it, from the inputs the timer makes (the figures a capture run draws, a few per view)
FIGURES = {
    "measured (one per view)": "measured_figure(ref, u, left_out, ('kept', 'dark', 'flow', 'edge'), 'camera 1')",
    "sensing (one per view, realistic sensing)": "sensing_figure(ref, ref, u, u + 0.1)",
    "held out (one per held-out view)": "heldout_figure(u, u + 0.1, 'px', 'camera 4', block_px=8)",
    "slices": "slice_figure(T, box, T, 'slices')",
    "profiles": "profiles_figure(T, box, T, 'profiles')",
    "rig": "rig_figure(cameras, box, {4}, [(np.linalg.norm(u, axis=-1), 'd')] * 9)",
    "curves": "curves_figure(history, losses, 1200, 'rad')",
    "2-D masks": "masks_figure([np.linalg.norm(u, axis=-1)] * 8, [left_out == 0] * 8, [f'view {v}' for v in range(8)], "
                 "'px', block_px=8)",
}

TIMER = """
import json, sys, time
import numpy as np
from nerif.geometry import ProbeBox
from nerif.geometry.camera import arc_rig
from nerif.io.plots import *
rng = np.random.default_rng(0)
ref = (rng.random((320, 240)) * 255).astype(np.uint8)
u = rng.normal(size=(40, 30, 2))
left_out = (rng.random((40, 30)) < 0.1).astype(int) * 2
box = ProbeBox((30, 50, 30), 2.0)
T = 300 + 1500 * np.exp(-((np.indices(box.shape) - np.array(box.shape)[:, None, None, None] / 2) ** 2).sum(0) / 50)
cameras = arc_rig(n_cameras=9, width_px=240, height_px=320, binning=8)
history = [{"wall_time_s": 4.0 * i, "temperature_rmse_K": 40.0 / i, "iteration": 100 * i} for i in range(1, 19)]
losses = [(i, {"loss": 1.0 / i, "loss_discrete": 1.0 / i, "loss_boundary": 1e-4}) for i in range(1, 1800, 10)]
draw = lambda: png_bytes(eval(sys.argv[1]))
draw()
t = time.perf_counter()
size = len(draw())
print(json.dumps({"s": time.perf_counter() - t, "bytes": size}))
"""


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", nargs="*", default=[], help="git refs or folders to time beside this checkout")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/figures"))
    args = ap.parse_args(argv)
    rows = {}
    with ExitStack() as stack:
        trees = {"this checkout": REPO, **{ref: checkout(ref, stack) for ref in args.against}}
        for name, call in FIGURES.items():
            runs = alternating_runs(trees, args.repeats, TIMER, call)
            rows[name] = {label: sorted(r["s"] for r in got)[len(got) // 2] for label, got in runs.items()}
    labels = list(trees)
    lines = ["| figure | " + " | ".join(f"{lab} [s]" for lab in labels) + " |", "|---|" + "---|" * len(labels)]
    lines += [f"| {name} | " + " | ".join(f"{row[lab]:.3f}" for lab in labels) + " |" for name, row in rows.items()]
    write_report(args.out, "figures", {"median_s": rows, "repeats": args.repeats}, "\n".join(lines) + "\n")
    return rows


if __name__ == "__main__":
    main()
