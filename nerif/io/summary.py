"""Multirun summary: one table (markdown and CSV) of every job's metrics, written beside the runs; the idle workers a
sweep leaves, ended."""
from __future__ import annotations

import csv
import io
import json
import logging
import sys
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from nerif.export import atomic_write, write_json

log = logging.getLogger("nerif")
FAILED = "failed.json"  # written in a job's folder when the job failed: {"error": its one-sentence message}

COLUMNS = [("temperature_rmse_K", "T RMSE [K]", "{:.2f}"), ("temperature_rmse_flame_K", "T RMSE flame [K]", "{:.2f}"),
           ("sigma_relative_error", "sigma rel. error", "{:.4f}"),
           ("deflection_rmse", "deflection RMSE [rad, or sigma]", "{:.3e}"), ("wall_time_s", "wall time [s]", "{:.1f}"),
           ("ms_per_iteration", "ms/it", "{:.1f}"), ("samples_per_second", "samples/s", "{:.3g}"),
           ("samples_per_ray_mean", "samples/ray", "{:.1f}"),
           ("displacement_rmse_px", "displacement RMSE [px]", "{:.3f}"),
           ("heldout_deflection_rmse", "held-out deflection RMSE", "{:.4g}"),
           ("heldout_psnr_db", "held-out PSNR [dB]", "{:.2f}"),
           ("heldout_displacement_rmse_px", "held-out displacement RMSE [px]", "{:.3f}"),
           ("data_term_kept", "field kept (held out)", "{}"),
           ("T_peak_K", "peak T [K]", "{:.0f}"), ("T_std_at_peak_K", "its std [K]", "{:.0f}"),
           ("T_peak_interval_K", "its 2-std interval [K]", "{0[0]:.0f}-{0[1]:.0f}"),
           ("T_peak_error_K", "peak T error [K]", "{:+.0f}"), ("flame_volume_cm3", "flame volume [cm3]", "{:.3g}"),
           ("T_std_median_flame_K", "T std in the flame [K]", "{:.1f}"),
           ("uncertainty_coverage_2sigma", "truth within 2 std", "{:.3f}"), ("iterations", "iterations", "{}")]


def collect(sweep_dir: Path) -> list[dict]:
    """One row per job folder: its overrides as 'config', plus the metric columns (a finished job) or its
    'error' (a failed one: a ``failed.json`` and no metrics)."""
    rows = []
    for job in sorted((p for p in Path(sweep_dir).iterdir() if p.is_dir()), key=lambda p: p.name):
        mfile, ffile = job / "metrics.json", job / FAILED
        if not (mfile.is_file() or ffile.is_file()):
            continue
        ov_file = job / ".hydra" / "overrides.yaml"
        overrides = OmegaConf.to_container(OmegaConf.load(ov_file)) if ov_file.is_file() else [job.name]
        row = {"config": " ".join(overrides) or "(defaults)"}
        if mfile.is_file():
            m = json.loads(mfile.read_text())
            row.update({k: m.get(k) for k, _, _ in COLUMNS})
        else:
            row["error"] = json.loads(ffile.read_text()).get("error", "failed")
        rows.append(row)
    return rows


def write_tables(rows: list[dict], folder: Path, stem: str = "summary", header: str = "") -> str:
    """``<stem>.md`` and ``<stem>.csv`` in ``folder``: one row per dict (its 'config' and metric columns).
    Returns the markdown."""
    present = [c for c in COLUMNS if any(r.get(c[0]) is not None for r in rows)]
    if any("error" in r for r in rows):
        present.append(("error", "error", "FAILED: {}"))
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
    """Hydra callback: after a multirun, tabulate the jobs' metrics in ``summary.md`` and ``summary.csv``, failed
    jobs with their error; the sweep then exits with status 1 if any job failed."""

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        from hydra.core.utils import JobStatus

        folder = Path(config.hydra.runtime.output_dir)
        if job_return.status == JobStatus.FAILED and not (folder / FAILED).is_file():  # an unexpected exception
            write_json({"error": f"{type(job_return._return_value).__name__}: {job_return._return_value}"},
                       folder / FAILED)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        rows = collect(sweep_dir) if sweep_dir.is_dir() else []
        if rows:
            print(write_tables(rows, sweep_dir), flush=True)
        failed = [r["config"] for r in rows if "error" in r]
        if failed:
            log.error("%d of %d jobs failed (%s); see %s", len(failed), len(rows), "; ".join(failed),
                      sweep_dir / "summary.md")
            sys.exit(1)


class IdleWorkersEnd(Callback):
    """Hydra callback: after a multirun through the joblib launcher, its idle worker processes are ended at once (left
    to the interpreter's exit, each a Python holding torch, they kept the prompt 3 s after the summary). Listed after
    :class:`MultirunSummary`, it runs before it (Hydra calls the end hooks in reverse)."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        loky = sys.modules.get("joblib.externals.loky.reusable_executor")  # imported only where a sweep used it
        executor = getattr(loky, "_executor", None)
        if executor is not None:
            executor.shutdown(wait=True, kill_workers=True)
