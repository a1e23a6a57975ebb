"""Numerical stress: extreme ambient states, hot flames, noise and degenerate rigs, at small scale on the CPU.

    python benchmarks/stress.py                      # every case, about 3 minutes on 2 cores
    python benchmarks/stress.py --cases T0_200 one_view --set train.iterations=600

Each case is a small Gaussian-blob scene (24^3 voxels of 2 mm, 6 views, 300 iterations of the default solver) with
some settings pushed to a limit. Reported: NaN/inf counts in the observations, the reconstruction and every
evaluation (must be zero), the temperature RMSE against the ambient field's, and the warnings the run gave (a
rig with fewer than 3 view directions, a flame at the prior's bound, empty 2-D masks). A case nerif refuses
with one sentence is reported with that sentence. Writes ``stress.json`` and ``stress.md`` under ``--out``.
"""
from __future__ import annotations

import argparse
import logging
import math
import time
import warnings
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import write_report  # noqa: E402
from nerif.data.diagnostics import ill_posed  # noqa: E402
from nerif.configs import compose, group  # noqa: E402
from nerif.data import DATASETS  # noqa: E402
from nerif.masks import MASKS  # noqa: E402
from nerif.metrics import rmse  # noqa: E402
from nerif.solvers import SOLVERS  # noqa: E402

# rays 1.4 mm apart at the blob (binning 10) and a hash no finer than they resolve (24 cells across the box);
# with 2.8 mm rays (binning 20) the default 96-cell hash fits the 2,300 rays without the blob (44 of 46 K)
BASE = ["device=cpu", "phantom=gaussian_blob", "phantom.shape=[24,24,24]", "phantom.voxel_mm=2.0",
        "phantom.width_mm=6.0", "rig.n_cameras=6", "rig.binning=10", "data.render_supersample=2",
        "field.finest_resolution=24", "field.log2_table_size=12", "sampler.samples_per_ray=32",
        "data.cache_dir=null", "train.iterations=300", "train.eval_every=100", "train.progress=false"]


def blob(T0: float, T_peak: float, n0: float = 1.00027) -> list[str]:
    return [f"phantom.T0={T0}", f"phantom.T_peak={T_peak}", f"phantom.n0={n0}", f"data.T_max={T_peak}"]


CASES = {
    "T0_200": blob(200.0, 1000.0), "T0_300": blob(300.0, 1200.0), "T0_1100": blob(1100.0, 2000.0),
    "T0_2400": blob(2400.0, 3000.0),
    "n0-1_1e-7": blob(296.15, 1200.0, 1.0000001), "n0-1_1e-5": blob(296.15, 1200.0, 1.00001),
    "n0-1_3e-4": blob(296.15, 1200.0, 1.0003),
    "flame_3000K": blob(296.15, 3000.0),
    "T_max_too_low": [*blob(296.15, 1500.0)[:3], "data.T_max=800"],
    "noise_5%": ["data.sensing=perpendicular", "data.deflection_noise=0.05"],
    "noise_10%": ["data.sensing=perpendicular", "data.deflection_noise=0.1"],
    "noise_40%": ["data.sensing=perpendicular", "data.deflection_noise=0.4"],  # ~10 % of the deflection range
    "one_view": ["rig.n_cameras=1"],
    "three_views_one_angle": ["rig.angles_deg=[30.0,30.0,30.0]"],
    "one_view_no_signal": ["silence_view=2"],
    "every_view_no_signal": ["phantom.T_peak=296.15", "mask=none"],
}


def nonfinite(x) -> int:
    return int((~np.isfinite(np.asarray(x, dtype=np.float64))).sum())


def run_case(overrides: list[str], extra: list[str]) -> dict:
    """One case through the same building blocks as ``python -m nerif``; NaN/inf counts, errors, warnings."""
    silence = [int(o.split("=")[1]) for o in overrides if o.startswith("silence_view=")]
    cfg = compose(BASE + [o for o in overrides if not o.startswith("silence_view=")] + extra)
    said: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record):
            if record.levelno >= logging.WARNING:
                said.append(record.getMessage())

    handler = Collect()
    logging.getLogger("nerif").addHandler(handler)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            torch.manual_seed(cfg.seed)
            solver = SOLVERS.build(group(cfg, "solver"))
            scene = DATASETS.build(group(cfg, "data"))
            for v in silence:
                scene.eps[scene.view_slice(v)] = 0.0
            masks = MASKS.build(group(cfg, "mask"), scene=scene)
            solver.setup(scene, masks)
            said += ill_posed(scene)
            solver.fit(checkpoint_every=10**9, progress=False)
            sigma = solver.reconstruction()
            said += solver.saturation(sigma).get("warnings", [])
        said += [str(w.message) for w in caught]
    except ValueError as e:
        return {"refused": str(e), "time_s": time.perf_counter() - t0}
    finally:
        logging.getLogger("nerif").removeHandler(handler)
    amb, T_true = scene.ambient, scene.truth_T
    T = amb.temperature_from_sigma(sigma)
    history_bad = sum(nonfinite([v for v in h.values() if isinstance(v, float)]) for h in solver.history)
    return {"nonfinite_observations": nonfinite(scene.eps.numpy()), "nonfinite_sigma": nonfinite(sigma),
            "nonfinite_T": nonfinite(T), "nonfinite_history": history_bad,
            "temperature_rmse_K": rmse(T, T_true), "ambient_rmse_K": rmse(np.full_like(T_true, amb.T0), T_true),
            "T_peak_K": float(T_true.max()), "warnings": sorted(set(said)), "time_s": time.perf_counter() - t0}


def table(rows: dict[str, dict]) -> str:
    lines = ["| case | NaN/inf (obs, sigma, T, history) | T RMSE [K] | ambient field [K] | warnings or refusal |",
             "|---|---|---|---|---|"]
    for name, r in rows.items():
        if "refused" in r:
            lines.append(f"| {name} | - | - | - | refused: {r['refused']} |")
            continue
        bad = ", ".join(str(r[k]) for k in ("nonfinite_observations", "nonfinite_sigma", "nonfinite_T",
                                            "nonfinite_history"))
        err = r["temperature_rmse_K"]
        lines.append(f"| {name} | {bad} | {'nan' if not math.isfinite(err) else f'{err:.2f}'} | "
                     f"{r['ambient_rmse_K']:.2f} | {'; '.join(r['warnings']) or '-'} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every case")
    ap.add_argument("--out", default="benchmarks/results/stress")
    args = ap.parse_args(argv)
    out = Path(args.out)
    rows = {}
    for i, name in enumerate(args.cases):
        rows[name] = run_case(CASES[name], args.set)
        print(f"[{i + 1}/{len(args.cases)}] {name}: " + ", ".join(
            f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}" for k, v in rows[name].items()), flush=True)
    bad = [n for n, r in rows.items() if any(r.get(k, 0) for k in
                                             ("nonfinite_sigma", "nonfinite_T", "nonfinite_history"))]
    text = table(rows) + ("\nNo NaN or inf anywhere.\n" if not bad else f"\nNaN or inf in: {', '.join(bad)}\n")
    write_report(out, "stress", {"settings": args.set, "rows": rows}, text)
    return rows


if __name__ == "__main__":
    main()
