"""Accuracy against time: the neural field and voxel CGLS variants on the same scenes, side by side.

    python benchmarks/accuracy_time.py                       # 3 scenes x 9 configurations, default CPU scale
    python benchmarks/accuracy_time.py --scenes plume --configs cgls "nerif hash+discrete"
    python benchmarks/accuracy_time.py --scenes phantom5_ideal --set device=cuda +experiment=paper_phantom5

Every run goes through ``nerif.app.run`` (the code of ``python -m nerif``) in one process, one after the
other; each records the temperature RMSE at regular intervals of its own wall time (``train.eval_every``,
``solver.eval_every``). The regularised CGLS variants run for every weight in ``LAMBDAS`` (the sweep is
recorded) and the best is reported. Writes ``accuracy_time.json``, ``accuracy_time.md`` and one
``error_vs_time_<scene>.png`` per scene under ``--out``.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ablation import header, run_cells

from nerif.export import atomic_write, write_json
from nerif.io.plots import plt, save_figure

# Measured displacements carry no along-ray component; on Phantom 5, which the box cuts, the 3-D gate then
# costs the absolute level (190 K vs 16 K with mask=2d, benchmarks/RESULTS.md): that scene uses 2-D masks.
SCENES = {"phantom5_ideal": "mask=3d", "phantom5_realistic": "data.sensing=realistic mask=2d",
          "plume": "phantom=turbulent_plume mask=3d"}
NEURAL = {"nerif hash+discrete": "solver=nerif encoder=hash grad=discrete",
          "nerif frequency+discrete": "solver=nerif encoder=frequency grad=discrete"}
LAMBDAS = {"tikhonov": (1e-4, 1e-3, 1e-2), "tv": (1e-4, 1e-3, 1e-2)}


def configurations() -> dict[str, str]:
    cfgs = dict(NEURAL)
    cfgs["cgls"] = "solver=cgls"
    for reg, lams in LAMBDAS.items():
        for lam in lams:
            cfgs[f"cgls-{reg} lam={lam:g}"] = f"solver=cgls solver.regularizer={reg} solver.lam={lam:g}"
    return cfgs


def best(history: list[dict]) -> tuple[float, float]:
    """(lowest temperature RMSE, wall time when first reached)."""
    h = min(history, key=lambda m: m["temperature_rmse_K"])
    return h["temperature_rmse_K"], h["wall_time_s"]


def time_to_reach(history: list[dict], target: float):
    return next((m["wall_time_s"] for m in history if m["temperature_rmse_K"] <= target), None)


def summarise(runs: dict[str, dict]) -> list[dict]:
    """One row per configuration family (regularised CGLS: its best weight), with the time to reach the best
    plain/regularised CGLS error of the scene."""
    families: dict[str, dict] = {}
    for name, r in runs.items():
        fam = name.split(" lam=")[0]
        if fam not in families or best(r["history"])[0] < best(families[fam]["history"])[0]:
            families[fam] = dict(r, name=name)
    cgls_best = min(best(r["history"])[0] for f, r in families.items() if f.startswith("cgls"))
    rows = []
    for fam, r in families.items():
        err, t = best(r["history"])
        rows.append({"configuration": r["name"], "best_T_rmse_K": err, "time_to_best_s": t,
                     "time_to_best_cgls_error_s": time_to_reach(r["history"], cgls_best),
                     "ms_per_iteration": r.get("ms_per_iteration")})
    return rows


def table(scene: str, rows: list[dict]) -> str:
    lines = [f"### {scene}", "", "| configuration | best T RMSE [K] | time to best [s] | time to best CGLS error [s] |"
             " ms/it |", "|---|---|---|---|---|"]
    for r in rows:
        reach = r["time_to_best_cgls_error_s"]
        lines.append(f"| {r['configuration']} | {r['best_T_rmse_K']:.1f} | {r['time_to_best_s']:.1f} | "
                     f"{'never' if reach is None else f'{reach:.1f}'} | {r['ms_per_iteration']:.1f} |")
    return "\n".join(lines) + "\n"


def figure(scene: str, runs: dict[str, dict], rows: list[dict]):
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for r in rows:
        h = runs[r["configuration"]]["history"]
        ax.plot([m["wall_time_s"] for m in h], [m["temperature_rmse_K"] for m in h], "o-", ms=3,
                label=r["configuration"])
    ax.set_yscale("log")
    ax.set_xlabel("wall time [s]")
    ax.set_ylabel("temperature RMSE [K]")
    ax.set_title(scene, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--configs", nargs="+", default=None, help="names from the default list (all by default)")
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every run")
    ap.add_argument("--out", default="benchmarks/results/accuracy_time", help="output folder")
    args = ap.parse_args(argv)
    out = Path(args.out)
    cfgs = {k: v for k, v in configurations().items() if args.configs is None or k in args.configs}
    result, md = {"settings": args.set, "scenes": {}}, []
    for scene in args.scenes:
        settings = list(args.set) + SCENES[scene].split()
        rows = run_cells(list(cfgs.values()), settings, out / scene)
        runs = {name: row for name, row in zip(cfgs, rows)}
        summary = summarise(runs)
        result["scenes"][scene] = {"runs": runs, "summary": summary}
        md.append(table(scene, summary))
        save_figure(figure(scene, runs, summary), out / f"error_vs_time_{scene}.png")
        write_json(result, out / "accuracy_time.json")  # after every scene: a crash keeps what is done
    text = f"Accuracy against time on {header(args.set, rows)}\n\n" + "\n".join(md)
    atomic_write(out / "accuracy_time.md", lambda t: Path(t).write_text(text))
    print(text)
    return result


if __name__ == "__main__":
    main()
