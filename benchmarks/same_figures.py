"""A refactor's check: the same figures as another checkout's code, side by side in one run, and the wall time of
reading captures.

    python benchmarks/same_figures.py --against a714205          # this checkout against that commit
    python benchmarks/same_figures.py --against a714205 --only time

For this checkout and each ``--against`` (a git ref, checked out into a temporary worktree, or a folder of
another checkout), one after the other, each as ``python -m nerif`` in a subprocess with that checkout's code:
- the default run (synthetic default scene) and the shared data (``../shared/data``): the independent capture,
  its calibrated multi-camera twin (through the version-3 rig file of ``benchmarks/calibrated.py``), its dirty twin (refused or not: the exit status is compared) and the paper
  authors' Phantom 1 (held-out error; its files hold no truth): temperature RMSE, sigma error (relative), held-out
  displacement error and wall time, with each figure's ratio to the first checkout's;
- the wall time of a capture's preprocessing (rig file, images, optical flow: building the scene of the
  independent capture) and of a 5-frame time series (a capture of the flickering flame written once by this
  checkout, rendered cheaply: :data:`SERIES_RENDERING`; reconstructed at ``--series-iterations`` per frame).
Writes ``same_figures.json`` and ``same_figures.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from contextlib import ExitStack
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from speed import checkout  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
CAPTURES = ("independent_capture_bunsen", "independent_capture_bunsen_multicam", "independent_capture_bunsen_dirty")
FIGURES = ("temperature_rmse_K", "sigma_rmse", "sigma_relative_error", "heldout_displacement_rmse_px",
           "heldout_deflection_rmse")
# the series' images rendered quickly (8 aperture rays, no supersampling): what is timed is reading them
SERIES_RENDERING = ["data.sensor.aperture_rays=8", "data.render_supersample=1"]
PREPROCESS = """
import sys, time
from nerif.configs import compose, group
from nerif.data import DATASETS
from nerif.data.frames import FRAMES
cfg = compose(["data=capture", "data.root=" + sys.argv[1], "data.frames=null"])
data = group(cfg, "data")
t = time.perf_counter()
frames = FRAMES.build(data) or [None]  # every frame's files checked, as python -m nerif does first
for f in frames:
    DATASETS.build(data, frame=None if f is None else f.index, device="cpu")
print(time.perf_counter() - t)
"""


def cases(out_dir: Path) -> dict[str, list[str]]:
    """Case name -> ``python -m nerif`` overrides (the multicam capture read through a version-3 rig file made under
    ``out_dir``, as ``benchmarks/calibrated.py`` reads it)."""
    from calibrated import multicam_folder

    out = {"default scene": []}
    for name in CAPTURES:
        root = SHARED / name
        folder = multicam_folder(out_dir / "multicam", ideal=False) if name.endswith("multicam") else root
        out[name] = ["data=capture", f"data.root={folder.resolve()}", f"data.truth={root / 'volume.npz'}"]
    out["nirbos_phantom1"] = ["data=transforms", f"data.root={SHARED / 'nirbos_phantom1'}", "sampler.samples_per_ray=64"]
    return out


def output_folder(out: str) -> Path:
    """The benchmark's output folder ``out``, made, once the shared data are known to lie beside the checkout."""
    if not SHARED.is_dir():
        raise SystemExit(f"{SHARED} is missing: this benchmark needs the shared data beside the checkout")
    path = Path(out)
    path.mkdir(parents=True, exist_ok=True)
    return path


def run(tree: Path, overrides: list[str], folder: Path) -> dict:
    """One ``python -m nerif`` of ``tree``'s code: its metrics (empty if it wrote none), exit status, wall time
    and the last line of its error output."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "nerif", f"hydra.run.dir={folder.resolve()}", "train.progress=false",
                           *overrides], cwd=tree, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    metrics = folder / "metrics.json"
    m = json.loads(metrics.read_text()) if metrics.is_file() and not done.returncode else {}
    last = [line for line in done.stderr.splitlines() if line.strip()][-1:] or [""]
    return {**{k: m.get(k) for k in FIGURES}, "exit": done.returncode, "wall_s": wall, "message": last[0][:200]}


def timed(tree: Path, argv: list[str], printed: bool = False) -> float:
    """Wall time [s] of a python command run with ``tree``'s code (``printed``: the time it prints last instead,
    its own measurement without the interpreter's start)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t = time.perf_counter()
    done = subprocess.run([sys.executable, *argv], cwd=tree, env=env, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"{tree}: {' '.join(argv[:3])} failed: {done.stderr.strip().splitlines()[-1:]}")
    return float(done.stdout.split()[-1]) if printed else time.perf_counter() - t


def ratio(a, b) -> str:
    return f"{a / b:.4f}" if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b else "-"


def report(rows: dict, names: list[str]) -> str:
    first = names[0]
    lines = ["| case | checkout | T RMSE [K] | sigma error | held-out disp. [px] | exit | wall [s] | ratio to "
             f"{first} (T, sigma error, held-out) |", "|---|---|---|---|---|---|---|---|"]
    for case, per in rows["cases"].items():
        for name in names:
            r, r0 = per[name], per[first]
            fmt = (lambda v, f: f.format(v) if isinstance(v, (int, float)) else "-")
            lines.append(f"| {case} | {name} | {fmt(r['temperature_rmse_K'], '{:.3f}')} | "
                         f"{fmt(r['sigma_relative_error'], '{:.4f}')} | {fmt(r['heldout_displacement_rmse_px'], '{:.4f}')} | "
                         f"{r['exit']} | {r['wall_s']:.0f} | {ratio(r['temperature_rmse_K'], r0['temperature_rmse_K'])}, "
                         f"{ratio(r['sigma_relative_error'], r0['sigma_relative_error'])}, "
                         f"{ratio(r['heldout_displacement_rmse_px'], r0['heldout_displacement_rmse_px'])} |")
    if rows.get("times"):
        lines += ["", "| wall time [s] | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
        for what in next(iter(rows["times"].values())):
            lines.append(f"| {what} | " + " | ".join(f"{rows['times'][n][what]:.1f}" for n in names) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", nargs="+", required=True, help="git refs or folders of other checkouts")
    ap.add_argument("--only", choices=("all", "figures", "time"), default="all")
    ap.add_argument("--cases", nargs="*", default=None, help="a subset of the cases (default: all)")
    ap.add_argument("--series-iterations", type=int, default=200, help="iterations of each frame of the series")
    ap.add_argument("--out", default="benchmarks/results/same_figures")
    args = ap.parse_args(argv)
    out = output_folder(args.out)
    rows: dict = {"cases": {}, "times": {}}
    with ExitStack() as stack:
        trees = {"this checkout": REPO, **{ref: checkout(ref, stack) for ref in args.against}}
        names = list(trees)
        if args.only in ("all", "figures"):
            for case, overrides in cases(out).items():
                if args.cases and case not in args.cases:
                    continue
                rows["cases"][case] = {}
                for i, (name, tree) in enumerate(trees.items()):
                    r = run(tree, overrides, out / f"{case.replace(' ', '_')}_{i}")
                    rows["cases"][case][name] = r
                    print(f"{case} @ {name}: {r}", flush=True)
        if args.only in ("all", "time"):
            series = out / "series5"
            if not (series / "rig.yaml").is_file():
                timed(REPO, ["-m", "nerif.write_capture", str(series.resolve()), "phantom=flicker", "data.frames=5",
                             *SERIES_RENDERING, "--overwrite"])
            it = args.series_iterations
            for i, (name, tree) in enumerate(trees.items()):
                shutil.rmtree(out / f"series_run_{i}", ignore_errors=True)  # a run folder of an earlier benchmark
                t = {"preprocessing of independent_capture_bunsen (rig, images, flow)":
                     timed(tree, ["-c", PREPROCESS, str(SHARED / "independent_capture_bunsen")], printed=True),
                     "preprocessing of the 5-frame series (every frame checked, then each built)":
                     timed(tree, ["-c", PREPROCESS, str(series.resolve())], printed=True),
                     f"5-frame series ({it} iterations a frame)":
                     timed(tree, ["-m", "nerif", f"hydra.run.dir={(out / f'series_run_{i}').resolve()}",
                                  "train.progress=false", "data=capture", f"data.root={series.resolve()}",
                                  "data.frames=null", f"train.iterations={it}", f"sequence.iterations={it}",
                                  "train.eval_every=100000"])}
                rows["times"][name] = t
                print(f"{name}: {t}", flush=True)
    text = report(rows, names)
    print(text)
    (out / "same_figures.json").write_text(json.dumps(rows, indent=1))
    (out / "same_figures.md").write_text(text)
    return rows


if __name__ == "__main__":
    main()
