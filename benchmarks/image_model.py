"""How the image term's model of a view errs on images another program made: the photometric optimum's gain on the
true displacements, per interpolation of the reference (issue 46).

    python benchmarks/image_model.py                      # every clean shared capture with a true_disp.npz
    python benchmarks/image_model.py --views 0 4 8
    python benchmarks/image_model.py --nerif-chain poisson_disk wavelet_noise   # nerif's own images of the same

For each view, the residual ``I_ref(x + a u(x)) - I_dist(x)`` of both images high-passed as the image term does
(``data_term.highpass_px``, 8 px) is evaluated at every pixel that moves by more than 0.1 px, ``u`` the capture's
exact displacements (``true_disp.npz``); the factor ``a`` in [0.9, 1.1] that minimises the mean squared residual
(Brent's method, to 1e-5) is where the term's model is least: 1 for an unbiased model, above 1 where it reads the
displacements too large. Also the RMS residual at ``a = 1`` [8-bit code values]. Every registered interpolation
(:data:`nerif.sensing.interpolation.INTERPOLATIONS`) and scipy's quintic B-spline (a candidate the term does not
offer). The spread of a view's factor under the sensor noise alone is about 0.002 on the synthetic textures and 0.007
on the low-contrast real ones (measured on pairs made by exact band-limited interpolation): the table's mean over
the views, and its standard error, are what to read. Writes ``image_model.json`` and ``image_model.md`` under
``--out``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
from scipy import ndimage
from scipy.optimize import minimize_scalar

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from nerif.data.capture_images import capture_files, read_exposures  # noqa: E402
from nerif.data.rig_file import read_rig  # noqa: E402
from nerif.losses.images import bandpass  # noqa: E402
from nerif.export import to_uint8  # noqa: E402
from nerif.sensing.interpolation import INTERPOLATIONS, interpolation  # noqa: E402
from nerif.sensing.patterns import PATTERNS  # noqa: E402
from nerif.sensing.realistic import exposures  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
MODES = (*INTERPOLATIONS.names(), "quintic")
MARGIN = 12  # pixels of border left out


def reader(image: torch.Tensor, mode: str):
    """``x`` (P, 2) (column, row) -> ``image`` there: the image term's reading (:mod:`nerif.sensing.interpolation`),
    or for ``quintic`` scipy's quintic B-spline, which the image term does not offer (measured here as a candidate)."""
    if mode == "quintic":
        c = ndimage.spline_filter(image.numpy(), order=5, mode="mirror")
        return lambda x: torch.as_tensor(ndimage.map_coordinates(c, x.numpy()[:, ::-1].T, order=5, mode="mirror",
                                                                 prefilter=False))
    read = interpolation(mode)
    grid = read.grid(image)
    return lambda x: read.at(grid, x)


def true_displacements(root: Path, v: int) -> torch.Tensor:
    """(H, W, 2) the capture's exact displacements of view ``v`` [px] (column, row)."""
    return torch.as_tensor(np.load(root / "true_disp.npz")["disp"][v], dtype=torch.float64).permute(1, 2, 0)


def nerif_chain(u: torch.Tensor, pattern: str, samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """nerif's realistic exposures (:func:`nerif.sensing.realistic.exposures`: no blur, 1 % noise, 8-bit) of its
    ``pattern`` seen through ``u`` (H, W, 2) with ``samples`` points a pixel and axis: (reference, distorted)."""
    H, W = u.shape[:2]
    background = torch.as_tensor(PATTERNS.build({"name": pattern}, height=H, width=W, seed=seed, samples=samples))
    pair = exposures(background.double(), u, 0.0, 1e-4, 0.0, None, torch.Generator().manual_seed(seed),
                     samples=samples)
    return tuple(to_uint8(x) / 255.0 for x in pair)


def view_rows(name: str, v: int, r: np.ndarray, d: np.ndarray, u: torch.Tensor) -> list[dict]:
    """The optimum's gain and the residual at the truth of one view's reference ``r`` and distorted image ``d``
    (H, W) seen through ``u`` (H, W, 2) [px], per interpolation."""
    R, D = (bandpass(torch.as_tensor(np.asarray(a), dtype=torch.float64), 8.0) for a in (r, d))
    H, W = R.shape
    m = MARGIN
    rows, cols = torch.meshgrid(torch.arange(m, H - m), torch.arange(m, W - m), indexing="ij")
    uu = u[m:H - m, m:W - m].reshape(-1, 2)
    moving = uu.norm(dim=-1) > 0.1
    x = torch.stack([cols.reshape(-1), rows.reshape(-1)], -1)[moving].double()
    uu, observed = uu[moving], D[m:H - m, m:W - m].reshape(-1)[moving]
    out = []
    for mode in MODES:
        read = reader(R, mode)

        def mse(a):
            return float((read(x + a * uu) - observed).pow(2).mean())

        best = minimize_scalar(mse, bounds=(0.9, 1.1), method="bounded", options={"xatol": 1e-5}).x
        at_one = mse(1.0) ** 0.5 * 255
        out.append({"capture": name, "view": v, "mode": mode, "gain": float(best), "rms_at_truth": at_one})
        print(f"{name} view {v} {mode}: optimum at {out[-1]['gain']:.4f}x the truth, RMS {at_one:.4f}", flush=True)
    return out


def report(rows: list[dict]) -> str:
    lines = ["# The image term's model on independent captures", "",
             "Optimum [x the true displacements] (mean over the views +- its standard error) / RMS residual at the "
             "truth [8-bit code values]", "",
             "| capture | views | " + " | ".join(MODES) + " |", "|---|---|" + "---|" * len(MODES)]
    for cap in dict.fromkeys(r["capture"] for r in rows):
        cells = []
        for mode in MODES:
            sel = [r for r in rows if r["capture"] == cap and r["mode"] == mode]
            g = np.array([r["gain"] for r in sel])
            err = g.std(ddof=1) / np.sqrt(len(g)) if len(g) > 1 else float("nan")
            cells.append(f"{g.mean():.4f} +- {err:.4f} / {np.mean([r['rms_at_truth'] for r in sel]):.3f}")
        lines.append(f"| {cap} | {len(sel)} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n\nPixels moving by more than 0.1 px, both images high-passed (8 px).\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", nargs="+", type=int, default=None, help="views of each capture (default: every one)")
    ap.add_argument("--captures", nargs="*", default=None, metavar="NAME",
                    help="folder names under the shared data (default: every clean capture with a true_disp.npz)")
    ap.add_argument("--nerif-chain", nargs="*", default=[], metavar="PATTERN",
                    help="also nerif's realistic exposures of these patterns through each capture's exact "
                         "displacements, the pattern sampled at pixel centres (pixel_samples 1) and integrated over "
                         "the pixel (4): does nerif's chain make images the way another program does?")
    ap.add_argument("--out", default="benchmarks/results/image_model")
    args = ap.parse_args(argv)
    # the clean captures: a dirty one's images hold a shake, a gain ramp and the flame's light that no gain measures
    roots = sorted(p.parent for p in [*DATA.glob("*/true_disp.npz"), *DATA.glob("*/*/true_disp.npz")]
                   if "shake" not in np.load(p).files and (args.captures is None or p.parent.name in args.captures))
    if not roots:
        sys.exit(f"no capture with a true_disp.npz under {DATA}")
    rows = []
    for root in roots:
        rig = read_rig(root)
        distorted, references = capture_files(rig)
        for v in (range(len(distorted)) if args.views is None else args.views):
            (d,), _ = read_exposures([distorted[v]], rig.sensor_px)
            (r,), _ = read_exposures([references[v]], rig.sensor_px)
            u = true_displacements(root, v)
            rows += view_rows(root.name, v, r, d, u)
            for pattern in args.nerif_chain:
                for samples in (1, 4):
                    rows += view_rows(f"{root.name}, nerif's chain, {pattern}, pixel_samples {samples}", v,
                                      *nerif_chain(u, pattern, samples, v), u)
    write_report(Path(args.out), "image_model", {"rows": rows}, report(rows))
    return {"rows": rows}


if __name__ == "__main__":
    main()
