"""Occluders told from a pattern's own gaps (issue 70): :func:`nerif.sensing.occlusion.occluded` on synthetic
backgrounds of every density with objects on them, and on the shared real pictures.

    python benchmarks/occlusion.py                 # about a minute on 2 cores
    python benchmarks/occlusion.py --sizes 512

Synthetic rows: each pattern (random dots 0.005-0.1 a px, 1-3 px across; Poisson-disk dots; wavelet noise; regular
dot grids of 12 and 24 px pitch), blurred by 1.5 px, ``--sizes`` px square: the share of the clean pattern taken
(the ideal is 0), then the same pattern with a dark model, its sting (11 px wide), a burner tube and a band out of
focus on it (``tests.test_occlusion.wind_tunnel``): the share of each object taken, and of the pattern 25 px or
more away from them. Real rows: the reference of each shared capture and real pair, measured as the stage does
(its texture's width and shrink factor): the share occluded; for the stratified pair also its textured centre
(rows 32-46 %, columns 20-80 %: should be 0) and its blocked bottom-left corner (should be 1).

Writes ``occlusion.json`` and ``occlusion.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch
from scipy import ndimage

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(ROOT))

from ablation import write_report  # noqa: E402
from tests.test_occlusion import wind_tunnel  # noqa: E402

from nerif.sensing.imaging import diffraction_blur  # noqa: E402
from nerif.sensing.measurement import _texture  # noqa: E402
from nerif.sensing.occlusion import occluded  # noqa: E402
from nerif.sensing.patterns import PATTERNS  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
PATTERN_SPECS = {f"random dots {d} /px, {r} px": {"name": "random_dots", "density": d, "radius_px": r}
                 for d, r in ((0.005, 2.0), (0.01, 1.0), (0.02, 1.0), (0.03, 2.0), (0.04, 1.0), (0.1, 2.5))}
PATTERN_SPECS.update({"Poisson-disk dots": {"name": "poisson_disk"}, "wavelet noise": {"name": "wavelet_noise"},
                      "dot grid 12 px": {"name": "dot_grid", "pitch_px": 12.0, "radius_px": 3.0},
                      "dot grid 24 px": {"name": "dot_grid", "pitch_px": 24.0, "radius_px": 4.0}})
OBJECTS = ("model", "sting", "burner", "band")


def synthetic_row(name: str, spec: dict, size: int) -> dict:
    img = PATTERNS.build(spec, height=size, width=size, seed=1)
    img = diffraction_blur(torch.as_tensor(np.float32(img)), 1.5).numpy()
    row = {"pattern": name, "size_px": size, "clean_taken": float(occluded(img).mean())}
    dirty, where = wind_tunnel(img)
    hidden = occluded(dirty)
    row.update({k: float(hidden[where[k]].mean()) for k in OBJECTS})
    near = ndimage.binary_dilation(np.any(list(where.values()), axis=0), iterations=25)
    row["pattern_taken"] = float(hidden[~near].mean())
    return row


def real_rows() -> list[dict]:
    """Each shared reference as the measurement stage reads it."""
    paths = [("stratified pair", SHARED / "real_pair_stratified" / "reference.tif")]
    for folder in sorted(SHARED.glob("independent_capture_*")) + sorted(SHARED.glob("real_background_*")):
        paths.append((folder.name, folder / "reference_00.png"))
    paths += [(p.parent.name, p) for p in sorted(SHARED.glob("independent_family/*/reference_00.png"))]
    rows = []
    for name, path in paths:
        if not path.exists():
            continue
        raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        ref = raw.astype(np.float32) / float(np.iinfo(raw.dtype).max)
        ref = ref.mean(-1) if ref.ndim == 3 else ref
        f, small, width, contrast = _texture(ref, "auto")
        hidden = occluded(small, 0.25, width, contrast)
        row = {"picture": name, "occluded": float(hidden.mean())}
        if name == "stratified pair":
            h, w = hidden.shape
            row["centre_taken"] = float(hidden[int(0.32 * h):int(0.46 * h), int(0.2 * w):int(0.8 * w)].mean())
            row["corner_taken"] = float(hidden[int(262 / 288 * h):, :int(28 / 215 * w)].mean())
        rows.append(row)
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", type=int, default=[512, 1024])
    ap.add_argument("--out", default="benchmarks/results/occlusion", help="output folder")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    synthetic = [synthetic_row(name, spec, size) for size in args.sizes for name, spec in PATTERN_SPECS.items()]
    real = real_rows()
    lines = ["| pattern | px | clean pattern taken | " + " | ".join(OBJECTS) + " | pattern taken beside them |",
             "|---|---|---|" + "---|" * len(OBJECTS) + "---|"]
    lines += [f"| {r['pattern']} | {r['size_px']} | {r['clean_taken']:.4f} | "
              + " | ".join(f"{r[k]:.2f}" for k in OBJECTS) + f" | {r['pattern_taken']:.4f} |" for r in synthetic]
    lines += ["", "| real picture | occluded | textured centre taken | blocked corner taken |", "|---|---|---|---|"]
    lines += [f"| {r['picture']} | {r['occluded']:.4f} | {r.get('centre_taken', float('nan')):.3f} | "
              f"{r.get('corner_taken', float('nan')):.2f} |" for r in real]
    lines.append(f"\n{time.perf_counter() - t0:.0f} s")
    payload = {"synthetic": synthetic, "real": real}
    write_report(Path(args.out), "occlusion", payload, "\n".join(lines) + "\n")
    return payload


if __name__ == "__main__":
    main()
