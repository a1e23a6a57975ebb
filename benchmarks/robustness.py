"""Robustness to sensing: temperature RMSE against image noise (at f/32) and against f-number (noise-free).

    python benchmarks/robustness.py                      # default scene, the 7 cells of conf/robustness/
    python benchmarks/robustness.py --set encoder=frequency --out benchmarks/results/robustness_freq

Runs one Hydra multirun (``python -m nerif -m +robustness=...``; its ``summary.md`` / ``summary.csv`` land in
the sweep folder), then writes ``robustness.json`` and ``robustness.png`` (RMSE against noise variance and
against f-number, with the flow's displacement RMSE) there.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from omegaconf import OmegaConf

from nerif.export import write_json
from nerif.io.plots import plt, save_figure

CELLS = "noise_0,noise_1e-4,noise_1e-3,noise_1e-2,f_8,f_16,f_64"


def collect(sweep: Path) -> list[dict]:
    rows = []
    for m in sorted(sweep.glob("*/metrics.json")):
        cfg = OmegaConf.load(m.parent / ".hydra" / "config.yaml")
        met = json.loads(m.read_text())
        rows.append({"noise_variance": float(cfg.data.sensor.noise_variance), "f_number": float(cfg.rig.f_number),
                     **{k: met.get(k) for k in ("temperature_rmse_K", "temperature_rmse_flame_K",
                                                "displacement_rmse_px", "circle_of_confusion_px", "wall_time_s")}})
    return rows


def figure(rows: list[dict]):
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, key, fixed, label in ((axes[0], "noise_variance", ("f_number", 32.0), "noise variance (f/32)"),
                                  (axes[1], "f_number", ("noise_variance", 0.0), "f-number (noise-free)")):
        sel = sorted((r for r in rows if r[fixed[0]] == fixed[1]), key=lambda r: r[key])
        x = [max(r[key], 1e-5) if key == "noise_variance" else r[key] for r in sel]
        ax.plot(x, [r["temperature_rmse_K"] for r in sel], "o-", label="T RMSE [K]")
        ax.set_xscale("log")
        ax.set_xlabel(label + (" (0 drawn at 1e-5)" if key == "noise_variance" else ""))
        ax.set_ylabel("temperature RMSE [K]")
        tw = ax.twinx()
        tw.plot(x, [r["displacement_rmse_px"] for r in sel], "s--", color="C1", label="flow error [px]")
        tw.set_ylabel("displacement RMSE [px]", color="C1")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cells", default=CELLS, help="comma-separated options of the config group 'robustness'")
    ap.add_argument("--set", nargs="*", default=[], help="overrides applied to every cell")
    ap.add_argument("--out", default="benchmarks/results/robustness", help="sweep folder")
    args = ap.parse_args(argv)
    out = Path(args.out).resolve()
    cmd = [sys.executable, "-m", "nerif", "-m", f"+robustness={args.cells}", *args.set, "train.progress=false",
           f"hydra.sweep.dir={out}", "hydra.sweep.subdir=${hydra.job.num}_${hydra.job.override_dirname}"]
    print(" ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)
    rows = collect(out)
    write_json({"settings": args.set, "rows": rows}, out / "robustness.json")
    save_figure(figure(rows), out / "robustness.png")
    print("\n".join(json.dumps(r) for r in rows))
    return rows


if __name__ == "__main__":
    main()
