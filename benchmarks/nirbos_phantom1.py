"""The paper authors' Phantom 1 data in their own format: held-out deflection error, hash against frequency,
and nerif's 3-D mask (back-projected from their 2-D masks) against theirs.

    python benchmarks/nirbos_phantom1.py                                  # CPU-sized settings
    python benchmarks/nirbos_phantom1.py --set device=cuda data.binning=1 train.iterations=10000 \\
        sampler.samples_per_ray=256 field.finest_resolution=512 field.hash_levels=16 field.log2_table_size=19

Held-out views: ``transforms_val.json`` (views 1 and 2 again, a second rendering). Deflections and errors are
in sigma units (the data do not say delta_thre). Writes ``phantom1.json`` and ``phantom1.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from ablation import header, run_cells
from nerif.data.transforms import reference_mask3d
from nerif.export import write_json
from nerif.geometry import ProbeBox
from nerif.io.summary import write_tables

ROOT = Path(__file__).resolve().parents[2] / "shared" / "data" / "nirbos_phantom1"
SETTINGS = ["data=transforms", f"data.root={ROOT}", "data.binning=4", "sampler.samples_per_ray=64",
            "train.iterations=1500", "train.eval_every=300"]


def mask_iou(run_dir: Path, root: Path) -> dict:
    """Intersection over union of the run's 3-D mask (``mask3d.npz``) with the authors' ``3Dmask.mat``."""
    ours = np.load(run_dir / "mask3d.npz")["mask"].astype(bool)
    theirs = reference_mask3d(str(root), ProbeBox(ours.shape, float(np.load(run_dir / "mask3d.npz")["voxel_mm"])))
    return {"mask_iou": float((ours & theirs).sum() / (ours | theirs).sum()), "mask_fraction_ours": float(ours.mean()),
            "mask_fraction_theirs": float(theirs.mean()),
            "theirs_outside_ours": float((theirs & ~ours).sum() / theirs.sum()),
            "ours_outside_theirs": float((ours & ~theirs).sum() / ours.sum())}


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cells", nargs="+", default=["encoder=hash", "encoder=frequency"])
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every cell (after the defaults)")
    ap.add_argument("--out", default="benchmarks/results/phantom1")
    args = ap.parse_args(argv)
    out, settings = Path(args.out), SETTINGS + args.set
    rows = run_cells(args.cells, settings, out)
    first = sorted(out.glob("0_*"))[0]
    if (first / "mask3d.npz").is_file():
        iou = mask_iou(first, ROOT)
        print("3-D mask against the authors' 3Dmask.mat: " + ", ".join(f"{k} {v:.3f}" for k, v in iou.items()))
    else:
        iou = {}
    write_json({"settings": settings, "rows": rows, "mask": iou}, out / "phantom1.json")
    print(write_tables(rows, out, "phantom1", "Phantom 1 (paper's format) on " + header(settings, rows)))
    return rows


if __name__ == "__main__":
    main()
