"""Training on the images against training on the optical flow, and the voxel solver both ways (issue 27).

    python benchmarks/images.py                                 # every scene (CPU: hours on 2 cores)
    python benchmarks/images.py --scenes realistic capture      # some of them
    python benchmarks/images.py --only nerif --resume           # the neural runs; finished runs read back

Scenes (``--scenes``):
- ``realistic``: Phantom 5 at the default scale through the realistic chain, ``--seeds`` draws (training seed and
  background pattern);
- ``axisymmetric``, ``plume``: the axisymmetric flame and the turbulent plume, realistic;
- ``glow``: the default scene with the flame's own light (30 % of the background's mean brightness, shaped like
  the flame's projection) and a 10 % gain drift between the exposures;
- ``capture``: ``../shared/data/independent_capture_bunsen``, rendered by a program that is not nerif (8-bit
  images, 1 % noise, exact lever arms), scored against its ``volume.npz``;
- ``multicam``: the same flame through ``independent_capture_bunsen_multicam``'s 10 calibrated cameras (its
  folder made under ``--out`` as ``benchmarks/calibrated.py`` makes it).

Per scene: nerif with ``data_term=flow``, with the images alone (``data_term=images data_term.flow_weight=0``)
and with its default (``data_term=auto``: the images with the flow term beside them); CGLS-TV two-step (the
flow's deflections) and unified (the images' linearised equations, ``data_term=images``) over a bracket of
weights, the best chosen with the truth (lowest error over every weight and evaluation: the harshest comparison
for nerif). Writes ``images.json`` and ``images.md`` (the table, and each target of the issue met or missed)
under ``--out``.

The same comparison on dirty data (the flame's light, vibration, a burner in the view; each effect alone and all
at once, with the measurement stage's findings against their truth) is ``benchmarks/dirty.py``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import header, run_arguments, run_named, write_report  # noqa: E402
from calibrated import MULTICAM, multicam_folder  # noqa: E402
from measured_data import t_max_of  # noqa: E402

CAPTURE = Path(__file__).resolve().parents[2] / "shared" / "data" / "independent_capture_bunsen"
TV_WEIGHTS = (1e-2, 1e-1, 1.0)


def scenes(names: list[str], seeds: list[int], out_dir: Path) -> dict[str, str]:
    """Scene name -> overrides (the multicam folder made under ``out_dir``)."""
    out = {}
    for name in names:
        if name == "realistic":
            for s in seeds:
                out[f"realistic, seed {s}"] = f"data.sensing=realistic seed={s} data.sensor.seed={s}"
        elif name == "axisymmetric":
            out[name] = "phantom=axisymmetric data.sensing=realistic"
        elif name == "plume":
            out[name] = f"phantom=turbulent_plume data.T_max={t_max_of('turbulent_plume')} data.sensing=realistic"
        elif name == "glow":
            out["glow and drift"] = "data.sensing=realistic data.sensor.luminosity=0.3 data.sensor.gain_drift=0.1"
        elif name == "capture":
            out["independent capture"] = (f"data=capture data.root={CAPTURE} "
                                          f"data.truth={CAPTURE / 'volume.npz'}")
        elif name == "multicam":
            root = multicam_folder(out_dir / "multicam", False)
            out["independent multicam capture"] = (f"data=capture data.root={root} "
                                                    f"data.truth={MULTICAM / 'volume.npz'}")
        else:
            raise SystemExit(f"unknown scene '{name}': realistic, axisymmetric, plume, glow, capture, multicam")
    return out


def cells(names: list[str], seeds: list[int], only: str, out_dir: Path) -> dict[tuple[str, str], str]:
    """(scene, method) -> overrides of every run."""
    out = {}
    for scene, base in scenes(names, seeds, out_dir).items():
        if only in ("all", "nerif"):
            out[scene, "nerif, flow"] = f"{base} data_term=flow"
            out[scene, "nerif, images alone"] = f"{base} data_term=images data_term.flow_weight=0"
            out[scene, "nerif, default"] = base
        if only in ("all", "cgls"):
            for term, what in (("flow", "two-step"), ("images", "unified")):
                for lam in TV_WEIGHTS:
                    out[scene, f"cgls-tv {what} {lam:g}"] = (f"{base} solver=cgls solver.regularizer=tv "
                                                             f"solver.lam={lam} data_term={term}")
    return out


def best(row: dict, key: str):
    vals = [h[key] for h in row["history"] if h.get(key) is not None]
    return min(vals) if vals else None


def report(rows: dict) -> str:
    """One table (T RMSE, sigma relative error, wall time per scene and method) and the issue's targets."""
    lines = ["| scene | method | T RMSE [K] | sigma rel. error | wall time [s] |", "|---|---|---|---|---|"]
    table: dict[str, dict[str, dict]] = {}
    for (scene, method), r in rows.items():
        if method.startswith("cgls"):
            what = "cgls-tv " + method.split()[1]
            T, s = best(r, "temperature_rmse_K"), best(r, "sigma_relative_error")
            old = table.setdefault(scene, {}).get(what)
            if old is None or (s is not None and s < old["sigma"]):
                table[scene][what] = {"T": T, "sigma": s, "time": r["wall_time_s"], "lam": method.split()[-1]}
        else:
            table.setdefault(scene, {})[method] = {"T": r.get("temperature_rmse_K"), "sigma": r.get("sigma_relative_error"),
                                                   "time": r["wall_time_s"]}
    for scene, methods in table.items():
        for method, v in methods.items():
            label = f"{method} (best: lam {v['lam']}, truth-picked)" if "lam" in v else method
            lines.append(f"| {scene} | {label} | {v['T']:.1f} | {v['sigma']:.4f} | {v['time']:.0f} |")
    checks = []

    def check(what, value, bound):
        checks.append(f"- {what}: {value:.3f} against at most {bound:.3f}: {'met' if value <= bound else 'MISSED'}")

    real = [m for s, m in table.items() if s.startswith("realistic, seed")]
    if real and all("nerif, default" in m for m in real):
        mean = sum(m["nerif, default"]["T"] for m in real) / len(real)
        check(f"default scene, realistic, default, mean of {len(real)} draw(s) [K]", mean, 11.0)
        flow = sum(m["nerif, flow"]["T"] for m in real if "nerif, flow" in m) / len(real)
        checks.append(f"- the same with the flow: {flow:.1f} K")
        check("wall time, default / flow (default scene)", sum(m["nerif, default"]["time"] for m in real)
              / sum(m["nerif, flow"]["time"] for m in real), 2.0)
    cap = table.get("independent capture", {})
    if {"nerif, default", "nerif, flow"} <= cap.keys():
        check("independent capture: sigma error, default / flow", cap["nerif, default"]["sigma"]
              / cap["nerif, flow"]["sigma"], 0.7)
        voxel = [v["sigma"] for k, v in cap.items() if k.startswith("cgls")]
        if voxel:
            check("independent capture: sigma error, default / the better voxel solver",
                  cap["nerif, default"]["sigma"] / min(voxel), 0.8)
    glow, plain = table.get("glow and drift", {}), table.get("realistic, seed 0", {})
    if "nerif, default" in glow and "nerif, default" in plain:
        check("with glow and drift / without (default)", glow["nerif, default"]["T"] / plain["nerif, default"]["T"],
              1.2)
    return "\n".join(lines) + "\n\n" + "\n".join(checks) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+",
                    default=["realistic", "axisymmetric", "plume", "glow", "capture", "multicam"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--only", choices=("all", "nerif", "cgls"), default="all")
    run_arguments(ap, "benchmarks/results/images")
    args = ap.parse_args(argv)
    rows = run_named(cells(args.scenes, args.seeds, args.only, Path(args.out).resolve()), args)
    text = f"Images against flow, {header(args.set, list(rows.values()))}\n\n{report(rows)}"
    write_report(Path(args.out), "images", {"settings": args.set, "rows": [{"scene": s, "method": m, **r}
                                                                for (s, m), r in rows.items()]}, text)
    return rows


if __name__ == "__main__":
    main()
