"""Known hot cores through the whole chain: how much of a core's peak a run keeps, and what the peak read through
the run's resolution (:mod:`nerif.resolution`) gives back (issue 66).

A Gaussian core in refractive index (``phantom=gaussian_blob``, standard deviation ``--widths`` mm, 1800 K at its
centre, on a voxel centre) on the shared captures' grid (60 x 100 x 60 voxels of 1 mm) seen by their rig (9 cameras
over 160 degrees, 360 x 640 px of 40 um, rays 4 px apart: 1.14 mm at the probe, the cameras focused on the background), each through the ideal chain (thin
rays, exact deflections) and the realistic one (aperture blur, a rendered background, 1 % noise, optical flow, the
images' term), every other setting the default:

    python benchmarks/resolution.py                              # widths 1 2 3 mm, both chains
    python benchmarks/resolution.py --widths 2 --chains ideal --resume

Per run: the true peak on the grid, the field's hottest voxel, the peak read through the run's resolution
(``T_peak_K``), whether the run calls the core resolved, the run's resolution ``s`` and the blur of the truth that
matches the field's peak (the point-spread the chain actually had at the core, found with the truth: what ``s``
models). Prints a table and writes ``resolution.json`` and ``resolution.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from same_figures import REPO, output_folder, run  # noqa: E402

RIG = ["rig.n_cameras=9", "rig.span_deg=160", "rig.width_px=360", "rig.height_px=640", "rig.pitch_um=40",
       "rig.binning=4"]
CHAINS = {"ideal": [], "realistic": ["data.sensing=realistic", "data.sensor.noise_variance=1e-4"]}
KEYS = ("T_peak_K", "T_peak_field_K", "T_peak_true_K", "T_peak_resolved", "resolution_mm", "sigma_relative_error")


def core_overrides(width_mm: float) -> list[str]:
    """A Gaussian core of ``width_mm`` at 1800 K on the shared captures' grid, centred on a voxel."""
    return ["phantom=gaussian_blob", "phantom.shape=[60,100,60]", "phantom.voxel_mm=1.0",
            "phantom.centre_mm=[0.5,0.5,0.5]", f"phantom.width_mm={width_mm:g}", "phantom.T_peak=1800",
            "uncertainty=none", *RIG]


def matching_blur_mm(folder: Path) -> float | None:
    """The standard deviation [mm] of the Gaussian blur that takes the truth's peak sigma to the field's (found with
    the truth, 0.01 mm steps to 3 mm); None where even 3 mm leaves the truth hotter."""
    from scipy.ndimage import gaussian_filter

    from nerif.physics import Ambient

    z = np.load(folder / "reconstruction.npz")
    amb = Ambient(T0=float(z["T0"]), n0=float(z["n0"]), T_max=2000.0)
    truth, field, voxel = amb.sigma_from_temperature(z["T_true"]), float(z["sigma"].min()), float(z["voxel_mm"])
    for s in np.arange(0.0, 3.0, 0.01):
        if gaussian_filter(truth, s / voxel, mode="nearest").min() >= field:
            return float(s)
    return None


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--widths", nargs="+", type=float, default=[1.0, 2.0, 3.0], help="core widths [mm] (std)")
    ap.add_argument("--chains", nargs="+", choices=list(CHAINS), default=list(CHAINS))
    ap.add_argument("--resume", action="store_true", help="read back the runs an earlier call finished")
    ap.add_argument("--out", default="benchmarks/results/resolution")
    args = ap.parse_args(argv)
    out = output_folder(args.out)
    rows = []
    for chain in args.chains:
        for w in args.widths:
            folder = out / f"{chain}-{w:g}mm"
            metrics = folder / "metrics.json"
            if not (args.resume and metrics.is_file()):
                r = run(REPO, [*core_overrides(w), *CHAINS[chain]], folder)
                if r["exit"]:
                    print(f"{chain} {w:g} mm: exit {r['exit']}: {r['message']}", flush=True)
                    continue
            m = json.loads(metrics.read_text())
            row = {"chain": chain, "width_mm": w, **{k: m.get(k) for k in KEYS}, "matching_blur_mm":
                   matching_blur_mm(folder)}
            rows.append(row)
            print(row, flush=True)
    lines = ["| chain | core width [mm] | true peak [K] | field's peak [K] | read through the resolution [K] | "
             "resolved | s [mm] | the truth's blur that matches the field [mm] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        blur = "-" if r["matching_blur_mm"] is None else f"{r['matching_blur_mm']:.2f}"
        lines.append(f"| {r['chain']} | {r['width_mm']:g} | {r['T_peak_true_K']:.0f} | {r['T_peak_field_K']:.0f} | "
                     f"{r['T_peak_K']:.0f} | {'yes' if r['T_peak_resolved'] else 'no'} | {r['resolution_mm']:.2f} | "
                     f"{blur} |")
    text = "\n".join(lines) + "\n"
    print(text)
    (out / "resolution.json").write_text(json.dumps(rows, indent=1))
    (out / "resolution.md").write_text(text)
    return {"rows": rows}


if __name__ == "__main__":
    main()
