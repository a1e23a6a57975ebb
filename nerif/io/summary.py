"""Multirun summary: one table (markdown and CSV) of every job's metrics, written beside the runs."""
from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from nerif.io.export import atomic_write

COLUMNS = [("temperature_rmse_K", "T RMSE [K]", "{:.2f}"), ("temperature_rmse_flame_K", "T RMSE flame [K]", "{:.2f}"),
           ("deflection_rmse", "deflection RMSE [rad, or sigma]", "{:.3e}"), ("wall_time_s", "wall time [s]", "{:.1f}"),
           ("ms_per_iteration", "ms/it", "{:.1f}"), ("samples_per_second", "samples/s", "{:.3g}"),
           ("samples_per_ray_mean", "samples/ray", "{:.1f}"),
           ("displacement_rmse_px", "displacement RMSE [px]", "{:.3f}"),
           ("heldout_deflection_rmse", "held-out deflection RMSE", "{:.4g}"),
           ("heldout_psnr_db", "held-out PSNR [dB]", "{:.2f}"),
           ("heldout_displacement_rmse_px", "held-out displacement RMSE [px]", "{:.3f}"),
           ("iterations", "iterations", "{}")]


def collect(sweep_dir: Path) -> list[dict]:
    """One row per job folder with a metrics.json: its overrides as 'config' plus the metric columns."""
    rows = []
    for mfile in sorted(Path(sweep_dir).glob("*/metrics.json"), key=lambda p: p.parent.name):
        ov_file = mfile.parent / ".hydra" / "overrides.yaml"
        overrides = OmegaConf.to_container(OmegaConf.load(ov_file)) if ov_file.is_file() else [mfile.parent.name]
        m = json.loads(mfile.read_text())
        rows.append({"config": " ".join(overrides) or "(defaults)", **{k: m.get(k) for k, _, _ in COLUMNS}})
    return rows


def write_tables(rows: list[dict], folder: Path, stem: str = "summary", header: str = "") -> str:
    """``<stem>.md`` and ``<stem>.csv`` in ``folder``: one row per dict (its 'config' and metric columns).
    Returns the markdown."""
    present = [c for c in COLUMNS if any(r.get(c[0]) is not None for r in rows)]
    md = ([header, ""] if header else []) + ["| config | " + " | ".join(h for _, h, _ in present) + " |",
                                             "|---" * (len(present) + 1) + "|"]
    for r in rows:
        md.append(f"| {r['config']} | " + " | ".join("" if r.get(k) is None else f.format(r[k]) for k, _, f in present) + " |")
    text = "\n".join(md) + "\n"
    atomic_write(folder / f"{stem}.md", lambda t: Path(t).write_text(text))
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["config"] + [k for k, _, _ in present])
    for r in rows:
        w.writerow([r["config"]] + [r.get(k) for k, _, _ in present])
    atomic_write(folder / f"{stem}.csv", lambda t: Path(t).write_text(buf.getvalue()))
    return text


class MultirunSummary(Callback):
    """Hydra callback: after a multirun, tabulate the jobs' metrics in ``summary.md`` and ``summary.csv``."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        rows = collect(sweep_dir)
        if rows:
            print(write_tables(rows, sweep_dir), flush=True)
