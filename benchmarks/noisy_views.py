"""Views of unequal noise: does weighing each view by its images' noise help? (issue 47)

    python benchmarks/noisy_views.py                           # CGLS-TV, views 2 and 5 at 3x the noise
    python benchmarks/noisy_views.py --cgls "solver.regularizer=tv solver.lam=0.01"
    python benchmarks/noisy_views.py --solvers cgls nerif --views 2 5 --factor 3

A copy of ``../shared/data/independent_capture_bunsen`` whose views ``--views`` hold ``--factor`` times the images'
noise (Gaussian noise added to both exposures of those views, so that their total is that factor times the 1 % the
capture was made with; 8-bit, clipped), reconstructed by each solver with ``data_term.noise_weighted`` true and
false, scored against the capture's truth. Prints the table and writes ``noisy_views.json`` and ``noisy_views.md``
under ``--out``.
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from same_figures import REPO, SHARED, output_folder, run  # noqa: E402

CAPTURE = SHARED / "independent_capture_bunsen"
MADE_WITH = 0.01  # the capture's noise, as its README says [full scale]
SOLVERS = {"cgls": ["solver=cgls"], "nerif": []}
CGLS_TV = "solver.regularizer=tv solver.lam=0.1"  # plain CGLS overfits the capture (sigma error above 2)


def noisier(root: Path, views: list[int], factor: float, seed: int = 0) -> Path:
    """The capture copied to ``root`` with ``views``' images ``factor`` times as noisy (unless already there)."""
    if (root / "rig.yaml").is_file():
        return root
    tmp = root.with_name(root.name + ".part")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(CAPTURE, tmp)
    extra = 255 * MADE_WITH * np.sqrt(factor ** 2 - 1)  # added in quadrature to the noise already there
    rng = np.random.default_rng(seed)
    for v in views:
        for kind in ("distorted", "reference"):
            path = tmp / f"{kind}_{v:02d}.png"
            image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float64)
            cv2.imwrite(str(path), np.clip(np.rint(image + rng.normal(0, extra, image.shape)), 0, 255).astype(np.uint8))
    tmp.rename(root)
    return root


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--views", nargs="+", type=int, default=[2, 5])
    ap.add_argument("--factor", type=float, default=3.0)
    ap.add_argument("--solvers", nargs="+", choices=list(SOLVERS), default=["cgls"])
    ap.add_argument("--cgls", default=CGLS_TV, help="the CGLS runs' own overrides (space-separated)")
    ap.add_argument("--out", default="benchmarks/results/noisy_views")
    args = ap.parse_args(argv)
    if args.factor < 1:
        raise SystemExit(f"--factor {args.factor}: at least 1 (the capture's own noise)")
    out = output_folder(args.out)
    root = noisier(out / f"capture_views{'_'.join(map(str, args.views))}_x{args.factor:g}", args.views, args.factor)
    rows = {}
    for solver in args.solvers:
        for weighted in (True, False):
            name = f"{solver}, noise_weighted={str(weighted).lower()}"
            own = [*SOLVERS[solver], *(args.cgls.split() if solver == "cgls" else [])]
            name += f" ({' '.join(own[1:])})" if own[1:] else ""
            folder = out / "runs" / re.sub(r"[^A-Za-z0-9_.-]+", "_", name)
            r = run(REPO, ["data=capture", f"data.root={root}", f"data.truth={CAPTURE / 'volume.npz'}", *own,
                           f"data_term.noise_weighted={str(weighted).lower()}"], folder)
            m = json.loads((folder / "metrics.json").read_text()) if not r["exit"] else {}
            rows[name] = {"sigma_relative_error": r["sigma_relative_error"], "temperature_rmse_K": r["temperature_rmse_K"],
                          "noise": [(f or {}).get("noise") for f in (m.get("measurement") or {}).values()],
                          "exit": r["exit"], "message": r["message"], "wall_s": r["wall_s"]}
            print(name, rows[name], flush=True)
    lines = [f"Views {args.views} of independent_capture_bunsen at {args.factor:g}x the noise.", "",
             "| solver | sigma relative error | T RMSE [K] |", "|---|---|---|"]
    for name, r in rows.items():
        cells = (f"{r['sigma_relative_error']:.4f} | {r['temperature_rmse_K']:.2f}" if not r["exit"]
                 else f"exit {r['exit']}: {r['message']} |")
        lines.append(f"| {name} | {cells} |")
    text = "\n".join(lines) + "\n"
    write_report(out, "noisy_views", rows, text)  # atomically, and printed
    return rows


if __name__ == "__main__":
    main()
