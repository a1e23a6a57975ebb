"""Captures as they come off a real rig (issue 37): each effect alone and all at once, on nerif's realistic chain
(with its truth) and on the shared captures, side by side in one process.

    python benchmarks/dirty.py                     # every row (CPU: about 10 min on 2 cores)
    python benchmarks/dirty.py --rows capture dirty --resume

Rows (``--rows``):
- ``clean``: the default scene through the realistic chain;
- ``shake``: the same with camera vibration, each view's distorted image moved by a random 0.1 px RMS per axis
  (``data.sensor.shake_px``);
- ``light``: the flame's own light (30 % of the background's mean at its brightest) and an uneven illumination drift
  (a gain ramping from 1 to 1.1 across the distorted image);
- ``burner``: an opaque burner tube on the axis, 6 mm in radius, its top at the probe box's bottom face
  (``data.sensor.burner_radius_mm``);
- ``all``: all three;
- ``capture``: ``../shared/data/independent_capture_bunsen`` (rendered by a separate program), scored against its
  ``volume.npz``;
- ``dirty``: ``../shared/data/independent_capture_bunsen_dirty``: the same flame with the flame's light, a gain
  ramp, vibration and an opaque burner tube (its README); its true shakes and occluded pixels in
  ``true_disp.npz``.

Columns: sigma error, T RMSE, the flow's error against the true displacements (the chain's record), the largest
error of the shakes found against the true ones, the shares of pixels left out as saturated, occluded, unmeasured
and rejected (mean over the views), the true share of occluded pixels (the ray grid's blocks that see some of the
burner), and the wall time. Writes ``dirty.json`` and ``dirty.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import cell_folder, header, run_arguments, run_named, write_report  # noqa: E402

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
LEFT_OUT = ("saturated", "occluded", "unmeasured", "rejected")


def rows_of(names: list[str]) -> dict[str, str]:
    real = {k: f"data=capture data.root={SHARED / f} data.truth={SHARED / f / 'volume.npz'}"
            for k, f in (("capture", "independent_capture_bunsen"), ("dirty", "independent_capture_bunsen_dirty"))}
    chain = "data.sensing=realistic"
    light = "data.sensor.luminosity=0.3 data.sensor.gain_ramp=0.1"
    burner = "data.sensor.burner_radius_mm=6"
    all_rows = {"clean": chain, "shake": f"{chain} data.sensor.shake_px=0.1", "light": f"{chain} {light}",
                "burner": f"{chain} {burner}", "all": f"{chain} {light} {burner} data.sensor.shake_px=0.1", **real}
    return {k: all_rows[k] for k in names}


def true_shakes(row_name: str, m: dict):
    """(V, 2) the true shakes of a row: the chain's record, or the dirty capture's ``true_disp.npz``."""
    if "shake_true_px" in m:
        return np.asarray(m["shake_true_px"])
    if row_name == "dirty":
        return np.load(SHARED / "independent_capture_bunsen_dirty" / "true_disp.npz")["shake"]
    return np.zeros((len(m.get("measurement") or {}), 2)) if row_name == "capture" else None  # it holds none


def shake_error(row_name: str, m: dict):
    """The largest error [px] of a shake found against the true one, over the views (None without a truth)."""
    truth, found = true_shakes(row_name, m), m.get("measurement")
    if truth is None or not found:
        return None
    names = sorted(found, key=lambda n: int(n.split()[1]))  # "camera 3 (60.0 deg)"
    est = np.array([found[n]["shake_px"] for n in names])
    idx = [int(n.split()[1]) for n in names]
    return float(np.abs(est - truth[idx]).max())


def true_occluded(row_name: str, m: dict):
    """The true share of occluded pixels (mean over the views; None without a truth): the chain's record, or the
    dirty capture's ``true_disp.npz`` on the run's ray grid (blocks of ``ray_binning`` with any occluded pixel)."""
    if "occluded_true" in m:
        return float(np.mean(m["occluded_true"]))
    if row_name == "dirty":
        occ = np.load(SHARED / "independent_capture_bunsen_dirty" / "true_disp.npz")["occluded"]
        b = int(m.get("ray_binning", 1))
        v, h, w = occ.shape
        return float(occ[:, :h - h % b, :w - w % b].reshape(v, h // b, b, w // b, b).any((2, 4)).mean())
    return 0.0 if row_name in ("clean", "shake", "light", "capture") else None


def report(rows: dict) -> str:
    lines = ["| row | sigma error | T RMSE [K] | flow error [px] | shake error (max) [px] | "
             + " | ".join(f"{k} [%]" for k in LEFT_OUT) + " | occluded, true [%] | wall [s] | warnings |",
             "|---|---|---|---|---|" + "---|" * len(LEFT_OUT) + "---|---|---|"]
    for name, m in rows.items():
        found = m.get("measurement") or {}
        share = {k: 100 * np.mean([f.get(k, 0.0) for f in found.values()]) if found else None for k in LEFT_OUT}
        err, occ = shake_error(name, m), true_occluded(name, m)
        fmt = (lambda v, f: f.format(v) if isinstance(v, (int, float)) and v is not None else "-")
        lines.append(f"| {name} | {fmt(m.get('sigma_relative_error'), '{:.4f}')} | "
                     f"{fmt(m.get('temperature_rmse_K'), '{:.2f}')} | {fmt(m.get('displacement_rmse_px'), '{:.4f}')} | "
                     f"{fmt(err, '{:.4f}')} | " + " | ".join(fmt(share[k], '{:.2f}') for k in LEFT_OUT)
                     + f" | {fmt(None if occ is None else 100 * occ, '{:.2f}')}"
                     + f" | {fmt(m.get('wall_time_s'), '{:.0f}')} | {len(m.get('warnings', []))} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    names = ["clean", "shake", "light", "burner", "all", "capture", "dirty"]
    ap.add_argument("--rows", nargs="+", default=names, choices=names)
    run_arguments(ap, "benchmarks/results/dirty")
    args = ap.parse_args(argv)
    runs = rows_of(args.rows)
    run_named(runs, args)
    rows = {name: json.loads((cell_folder(Path(args.out), i, cell) / "metrics.json").read_text())  # every figure
            for i, (name, cell) in enumerate(runs.items())}
    text = f"Dirty captures, {header(args.set, list(rows.values()))}\n\n{report(rows)}"
    payload = {k: {**{x: v for x, v in m.items() if x != "history"}, "shake_error_px": shake_error(k, m),
                   "occluded_true_share": true_occluded(k, m)} for k, m in rows.items()}
    write_report(Path(args.out), "dirty", payload, text)
    return rows


if __name__ == "__main__":
    main()
