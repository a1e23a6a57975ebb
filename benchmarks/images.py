"""Training on the images against training on the optical flow, and the voxel solver both ways (issue 27).

    python benchmarks/images.py                                 # every scene (CPU: hours on 2 cores)
    python benchmarks/images.py --scenes realistic capture      # some of them
    python benchmarks/images.py --only nerif --resume           # the neural runs; finished runs read back
    python benchmarks/images.py --scenes capture dirty finer --only nerif --flows     # issue 39's rows
    python benchmarks/images.py --sizes 1 2 4 7 10.5            # time and memory up to 25 megapixels a view

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

Issue 39 adds:
- ``dirty``: ``independent_capture_bunsen_dirty`` (the flame's light, a gain ramp, vibration, a burner);
- ``finer``: the shared capture's flame (its ``volume.npz`` as ``phantom=file``) written by ``nerif.write_capture``
  twice, at the shared rig's 360 x 640 px of 40 um (``data.binning=4``) and at 4x finer pixels, 1440 x 2560 px of
  10 um, with the same Poisson-disk background in millimetres and the same ray grid (``data.binning=16``): does the
  default profit from many pixels? Each also with ``measure.flow_factor=1`` (the flow on the images as they are);
- ``--flows``: every displacement estimator of ``benchmarks/flows.py`` against ``true_disp.npz`` on the shared
  captures (error, gain, time a view);
- ``--sizes K ...``: the default on a 10-view capture of the same flame at K times the shared rig's pixels a side
  (K = 10.5: 3780 x 6720 px, 25.4 megapixels), each run in its own process: preprocessing (reading, measuring),
  training, peak memory. Needs ``../shared``.

The same comparison on dirty data (the flame's light, vibration, a burner in the view; each effect alone and all
at once, with the measurement stage's findings against their truth) is ``benchmarks/dirty.py``.
"""
from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ablation import header, run_arguments, run_named, write_report  # noqa: E402
from calibrated import MULTICAM, multicam_folder  # noqa: E402
from measured_data import t_max_of  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
CAPTURE = DATA / "independent_capture_bunsen"
DIRTY = DATA / "independent_capture_bunsen_dirty"
TV_WEIGHTS = (1e-2, 1e-1, 1.0)
ANGLES = [0, 20, 40, 60, 80, 100, 120, 140, 160]  # the shared rig's views


def finer_capture(root: Path, k: float, angles: list = ANGLES, flame: Path = CAPTURE, extra: tuple = ()) -> Path:
    """The shared capture's flame (or the independent capture ``flame``'s) written by ``nerif.write_capture`` (its
    own process) at ``k`` times the shared rig's pixels a side (pitch 40 / k um, the Poisson-disk background and the
    rays' spacing the same in millimetres, 1 % noise, f/32; ``extra``: more overrides), unless ``root`` already
    holds it."""
    if (root / "rig.yaml").is_file():
        return root
    if not float(4 * k).is_integer():
        raise SystemExit(f"--sizes {k}: 4 x K must be whole (the rays 4 shared pixels apart)")
    w, h = int(round(360 * k)), int(round(640 * k))
    subprocess.run([sys.executable, "-m", "nerif.write_capture", str(root), "phantom=file",
                    f"phantom.path={flame / 'volume.npz'}", "phantom.key=T", "phantom.voxel_mm=1.0",
                    f"data.T_max={t_max_of_capture(flame)}",
                    "data.render_supersample=1", f"rig.n_cameras={len(angles)}", f"rig.angles_deg={angles}",
                    f"rig.width_px={w}", f"rig.height_px={h}", f"rig.pitch_um={40 / k:g}", f"rig.binning={int(4 * k)}",
                    "data.sensing=realistic", "data.sensor.noise_variance=1e-4", f"pattern.spacing_px={4 * k:g}",
                    f"pattern.radius_px={1.2 * k:g}", *extra, "--overwrite"], check=True)
    return root


def t_max_of_capture(root: Path) -> float:
    """The hottest expected temperature [K] a capture's rig file names (its flame's ``delta_thre``)."""
    import yaml

    return float(yaml.safe_load((root / "rig.yaml").read_text()).get("T_max", 2000.0))


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
        elif name == "dirty":
            out["independent dirty capture"] = f"data=capture data.root={DIRTY} data.truth={DIRTY / 'volume.npz'}"
        elif name == "finer":
            truth = f"data.truth={CAPTURE / 'volume.npz'}"
            for k, label in ((1, "360 x 640 px"), (4, "1440 x 2560 px (4x finer)")):
                root = finer_capture(out_dir / f"finer_x{k}", k)
                out[f"written, {label}"] = f"data=capture data.root={root} data.binning={4 * k} {truth}"
                if k > 1:
                    out[f"written, {label}, flow on the images as they are"] = (
                        f"data=capture data.root={root} data.binning={4 * k} {truth} measure.flow_factor=1")
        elif name == "multicam":
            root = multicam_folder(out_dir / "multicam", False)
            out["independent multicam capture"] = (f"data=capture data.root={root} "
                                                    f"data.truth={MULTICAM / 'volume.npz'}")
        else:
            raise SystemExit(f"unknown scene '{name}': realistic, axisymmetric, plume, glow, capture, dirty, finer, "
                             "multicam")
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


SIZE_ANGLES = [0, 18, 36, 54, 72, 90, 108, 126, 144, 162]  # 10 views


def size_rows(factors: list[float], out_dir: Path, settings: list[str], resume: bool = False) -> list[dict]:
    """The default on a 10-view capture of the shared flame at each factor (:func:`finer_capture`), each run in
    its own process (its peak memory its own): megapixels a view, preprocessing (``setup_time_s``: reading,
    measuring every view, the masks), training (``wall_time_s``), peak memory, sigma error. ``resume``: a finished
    run is read back; else an earlier run's folder is replaced."""
    rows = []
    for k in factors:
        root = finer_capture(out_dir / f"size_x{k:g}", k, SIZE_ANGLES)
        run_dir = out_dir / f"size_x{k:g}_run"
        finished = resume and (run_dir / "metrics.json").is_file()
        if run_dir.exists() and not finished:
            shutil.rmtree(run_dir)
        t0 = time.perf_counter()
        done = subprocess.CompletedProcess([], 0) if finished else subprocess.run([sys.executable, "-m", "nerif", "data=capture", f"data.root={root}",
                               f"data.binning={int(4 * k)}", f"data.truth={CAPTURE / 'volume.npz'}",
                               f"hydra.run.dir={run_dir}", "train.progress=false", *settings])
        if done.returncode:
            rows.append({"factor": k, "failed": done.returncode})
            continue
        m = json.loads((run_dir / "metrics.json").read_text())
        rows.append({"factor": k, "megapixels": 360 * 640 * k * k / 1e6, "views": len(SIZE_ANGLES),
                     "preprocessing_s": m["setup_time_s"], "training_s": m["wall_time_s"],
                     "total_s": time.perf_counter() - t0, "peak_memory_gib": m.get("peak_memory_gib"),
                     "sigma_relative_error": m["sigma_relative_error"], "ms_per_iteration": m["ms_per_iteration_mean"]})
        print(f"x{k:g}: {rows[-1]}", flush=True)
    return rows


def size_report(rows: list[dict]) -> str:
    lines = ["| pixels a side | megapixels a view | preprocessing [s] | training [s] | ratio | ms a step | "
             "peak memory [GiB] | sigma rel. error |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "failed" in r:
            lines.append(f"| x{r['factor']:g} | failed (exit {r['failed']}) | | | | | | |")
            continue
        lines.append(f"| x{r['factor']:g} | {r['megapixels']:.1f} | {r['preprocessing_s']:.0f} | {r['training_s']:.0f} "
                     f"| {r['preprocessing_s'] / r['training_s']:.2f} | {r['ms_per_iteration']:.1f} "
                     f"| {r['peak_memory_gib']:.1f} | {r['sigma_relative_error']:.4f} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="*", default=None,
                    help="default: realistic axisymmetric plume glow capture multicam, none with --flows or --sizes")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--only", choices=("all", "nerif", "cgls"), default="all")
    ap.add_argument("--flows", action="store_true", help="the estimators against true_disp.npz (benchmarks/flows.py)")
    ap.add_argument("--sizes", nargs="*", type=float, default=[],
                    help="pixels a side over the shared rig's, one 10-view capture each (10.5: 25 megapixels)")
    run_arguments(ap, "benchmarks/results/images")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    payload, text = {"settings": args.set}, ""
    if args.scenes is None and not (args.flows or args.sizes):
        args.scenes = ["realistic", "axisymmetric", "plume", "glow", "capture", "multicam"]
    if args.scenes:
        rows = run_named(cells(args.scenes, args.seeds, args.only, out), args)
        text += f"Images against flow, {header(args.set, list(rows.values()))}\n\n{report(rows)}"
        payload["rows"] = [{"scene": s, "method": m, **r} for (s, m), r in rows.items()]
    if args.flows:
        import flows

        roots = sorted(p.parent for p in DATA.glob("*/true_disp.npz"))
        payload["flows"] = [row for root in roots for row in flows.capture_rows(root, None)]
        text += "\n" + flows.report(payload["flows"])
    if args.sizes:
        payload["sizes"] = size_rows(args.sizes, out, args.set, args.resume)
        text += ("\n## Time and memory against the image size (the default, 10 views)\n\n"
                 + size_report(payload["sizes"]))
    write_report(out, "images", payload, text)
    return payload


if __name__ == "__main__":
    main()
