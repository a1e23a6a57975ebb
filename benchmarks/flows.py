"""Displacement estimators against the exact displacements of the shared captures (issue 39).

    python benchmarks/flows.py                        # every estimator on every capture with a true_disp.npz
    python benchmarks/flows.py --views 0 4            # some views (all by default)
    python benchmarks/flows.py --captures family-103  # some captures (the family's members included)

Each estimator measures every view through the measurement stage (``nerif.sensing.measurement``, as a run does:
saturation, occlusion, the shake taken off, outliers rejected) on the capture's auto ray grid. Its displacements
are compared with ``true_disp.npz`` (less its ``shake``, where it records one) block-averaged to the same grid, on the pixels the stage kept, less 5 rays of
border: the RMS error [px of the full sensor], the RMS error over the RMS displacement, the gain (the least-squares
scale of the estimate on the truth: above 1, it overestimates) and the wall time of the stage a view. The
estimators are ``flow=`` configs: Farneback as shipped (``normalise_px=auto``) and without normalising, DIS
normalised over 8 px and auto. A per-pixel error is not the reconstruction's: a dense Lucas-Kanade flow with 15 %
less per-pixel error gave twice the sigma error (``benchmarks/RESULTS.md``). Writes ``flows.json`` and
``flows.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from nerif.data.capture import rig_geometry  # noqa: E402
from nerif.data.capture_images import capture_files, read_exposures  # noqa: E402
from nerif.data.rig_file import read_rig  # noqa: E402
from nerif.geometry import outside_the_box  # noqa: E402
from nerif.sensing.imaging import resample  # noqa: E402
from nerif.sensing.measurement import MEASUREMENT  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
ESTIMATORS = {
    "farneback (shipped, auto)": {"name": "farneback", "normalise_px": "auto"},
    "farneback, not normalised": {"name": "farneback", "normalise_px": None},
    "dis, normalised over 8 px": {"name": "dis", "normalise_px": 8.0},
    "dis, auto": {"name": "dis", "normalise_px": "auto"},
}
BORDER = 5  # rays of border left out of the scores


def score(u: np.ndarray, valid: np.ndarray, truth: np.ndarray) -> dict:
    """RMS error [px], relative error and gain of ``u`` (h, w, 2) against ``truth`` (h, w, 2) where ``valid``."""
    keep = valid.copy()
    keep[:BORDER], keep[-BORDER:], keep[:, :BORDER], keep[:, -BORDER:] = False, False, False, False
    e, t = u[keep], truth[keep]
    rms_t = float(np.sqrt((t * t).sum(-1).mean()))
    err = float(np.sqrt(((e - t) ** 2).sum(-1).mean()))
    return {"error_px": err, "relative": err / rms_t, "gain": float((e * t).sum() / (t * t).sum()),
            "kept": float(keep.mean())}


def capture_rows(root: Path, views: list[int] | None) -> list[dict]:
    rig = read_rig(root)
    exact = np.load(root / "true_disp.npz")
    truth = exact["disp"]  # (V, 2, H, W) [px of the full sensor]
    if "shake" in exact.files:  # the camera's shift between the exposures, which the stage takes off
        truth = truth - exact["shake"][:, :, None, None]
    full, cameras, roi, rays = rig_geometry(rig, "auto", "cpu")
    distorted, references = capture_files(rig)
    quiet = outside_the_box(cameras, rays[2], rays[3])
    rows = []
    for v in views if views is not None else range(rig.n_views):
        (d,), _ = read_exposures([distorted[v]], rig.sensor_px)
        (r,), _ = read_exposures([references[v]], rig.sensor_px)
        cam = cameras[v]
        t = resample(np.moveaxis(truth[v], 0, -1).astype(np.float32), cam.height, cam.width)
        for name, flow in ESTIMATORS.items():
            t0 = time.perf_counter()
            m = MEASUREMENT.build({"name": "default"}, distorted=d, reference=r, flow=flow,
                                  grid_px=(cam.height, cam.width), region=roi, quiet=quiet[v], name=cam.name)
            rows.append({"capture": root.name, "view": v, "estimator": name, "seconds": time.perf_counter() - t0,
                         **score(m.displacement, m.valid, t)})
            print(f"{root.name} view {v}: {name}: {rows[-1]['error_px']:.4f} px, gain {rows[-1]['gain']:.3f}",
                  flush=True)
    return rows


def report(rows: list[dict]) -> str:
    lines = ["# Displacement estimators against the exact displacements", "",
             "| capture | estimator | RMS error [px] | relative | gain | s a view |", "|---|---|---|---|---|---|"]
    for cap in dict.fromkeys(r["capture"] for r in rows):
        for name in ESTIMATORS:
            sel = [r for r in rows if r["capture"] == cap and r["estimator"] == name]
            mean = {k: float(np.mean([r[k] for r in sel])) for k in ("error_px", "relative", "gain", "seconds")}
            lines.append(f"| {cap} | {name} | {mean['error_px']:.4f} | {mean['relative']:.3f} | {mean['gain']:.3f} "
                         f"| {mean['seconds']:.2f} |")
    return "\n".join(lines) + "\n\nMeans over the views; scores on the ray grid, on the pixels the stage kept.\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", nargs="+", type=int, default=None, help="views to measure (all by default)")
    ap.add_argument("--captures", nargs="+", default=None,
                    help="folder names under the shared data (default: every capture with a true_disp.npz)")
    ap.add_argument("--out", default="benchmarks/results/flows", help="output folder")
    args = ap.parse_args(argv)
    roots = sorted(p.parent for p in [*DATA.glob("*/true_disp.npz"), *DATA.glob("*/*/true_disp.npz")]
                   if args.captures is None or p.parent.name in args.captures)
    if not roots:
        sys.exit(f"no capture with a true_disp.npz under {DATA}")
    rows = [row for root in roots for row in capture_rows(root, args.views)]
    write_report(Path(args.out), "flows", {"rows": rows}, report(rows))
    return {"rows": rows}


if __name__ == "__main__":
    main()
