"""A time series of a changing flame (``data.frames``): every frame reconstructed in turn, each warm-started from
the previous one's field, with per-frame outputs and the series' own.

Layout of the run folder::

    frame_0000/ ...          # every output of a single run (reconstruction.npz/.vti, metrics.json, checkpoint.pt)
    sequence.pvd             # ParaView: the frames' reconstruction.vti as one dataset in time
    frames.md, frames.csv    # one row of metrics per frame
    sequence.png             # the central vertical slice of every frame (over the truth where known)
    metrics.json             # the series: its frames' metrics, and their means
    tensorboard/             # per frame (step = frame index): its final metrics and slices

A frame is finished when its ``metrics.json`` exists; resuming the series (``train.resume=auto`` in its folder,
or a requeued Slurm job) keeps finished frames, continues an interrupted frame from its own checkpoint and
starts the next ones from their predecessors.
"""
from __future__ import annotations

import json
import logging
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from nerif.data.frames import FRAMES, Frame
from nerif.geometry import ProbeBox
from nerif.export import write_json, write_pvd
from nerif.io.headline import Headline, summary_line
from nerif.io.plots import save_figure, sequence_figure
from nerif.io.summary import COLUMNS, write_tables
from nerif.reconstruct import reconstruct, resuming
from nerif.solvers import SOLVERS
from nerif.units import declare, metric_units

log = logging.getLogger(__name__)

declare(n_frames="frames", frames_finished="frames", time_s="s", frame="(index)",
        text=("note", "frame_folder", "warm_start", "folder", "error"),
        containers={"frames": "(one row a frame, each unit by its name here)"})
# a frame's headline metrics: the multirun table's columns, and the held-out PSNR its summary line prints
FINAL_KEYS = tuple(k for k, _, _ in COLUMNS) + ("heldout_displacement_psnr_db",)


def frames_of(data: dict) -> Optional[list[Frame]]:
    """The frames a ``data`` config asks for, or None for one steady scene (a dataset without frames)."""
    if data["name"] not in FRAMES:
        return None
    return FRAMES.build(data)


def frame_folder(frame: Frame) -> str:
    return f"frame_{frame.index:04d}"


def frame_config(cfg: DictConfig, warm: bool) -> DictConfig:
    """The config of one frame: a warm-started frame trains ``sequence.iterations`` at ``sequence.lr``."""
    fc = OmegaConf.create(OmegaConf.to_container(cfg, resolve=False))
    if warm:
        fc.train.iterations = int(cfg.sequence.iterations)
        fc.train.lr = float(cfg.sequence.lr)
    return fc


def check_sequence(cfg: DictConfig) -> None:
    """The sequence settings, before any frame: one sentence for a bad one."""
    sc = cfg.sequence
    if not isinstance(sc.warm_start, bool):
        raise ValueError(f"sequence.warm_start={sc.warm_start}: true or false")
    if not (isinstance(sc.iterations, int) and sc.iterations >= 1):
        raise ValueError(f"sequence.iterations={sc.iterations}: at least 1 iteration per warm-started frame")
    if not float(sc.lr) > 0:
        raise ValueError(f"sequence.lr={sc.lr}: a positive learning rate")
    if sc.warm_start and not SOLVERS.get(cfg.solver.name).starts_from_previous:
        raise ValueError(f"solver={cfg.solver.name} cannot start a frame from the previous one: use "
                         "sequence.warm_start=false")
    if cfg.train.resume not in (None, "auto"):
        raise ValueError(f"train.resume={cfg.train.resume}: a time series resumes from its own folder, with "
                         "train.resume=auto hydra.run.dir=<the series' folder>")


def run_sequence(cfg: DictConfig, out_dir: Path, device: torch.device, frames: list[Frame], threads=None,
                 warned: tuple = ()) -> dict:
    """Reconstruct ``frames`` in turn into ``out_dir/frame_KKKK/``, each from the previous frame's final state
    (``sequence.warm_start``); write the series' outputs (also when interrupted, for the finished frames).
    Returns the series' metrics. ``threads``: the run's :class:`nerif.threads.ThreadTuner`, if any. ``warned``:
    the warnings the run gave before its frames, which each frame's ``metrics.json`` carries too."""
    t_start = time.perf_counter()
    check_sequence(cfg)
    again = resuming(cfg.train.resume)
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(log_dir=str(out_dir / "tensorboard"))
    rows: list[dict] = []
    previous, unit = None, None
    log.info("time series of %d frames (t = %.4g to %.4g s), %s", len(frames), frames[0].time_s, frames[-1].time_s,
             "each warm-started from the one before" if cfg.sequence.warm_start else "each from scratch")
    try:
        for j, f in enumerate(frames):
            folder = out_dir / frame_folder(f)
            warm = bool(cfg.sequence.warm_start) and previous is not None
            if again and (folder / "metrics.json").is_file():
                m = json.loads((folder / "metrics.json").read_text())
                log.info("frame %d (%d of %d) was finished before: kept", f.index, j + 1, len(frames))
            else:
                how = ("continued from its own checkpoint" if again and (folder / "checkpoint.pt").is_file()
                       else f"warm start from {previous.parent.name}" if warm else "cold start")
                log.info("frame %d (%d of %d, t = %.4g s): %s", f.index, j + 1, len(frames), f.time_s, how)
                m = reconstruct(frame_config(cfg, warm), folder, device, frame=f.index,
                                start_from=previous if warm else None,
                                about={"frame": f.index, "time_s": f.time_s, "warm_start": warm, "warnings": list(warned)},
                                resume_hint=f"the same command and train.resume=auto hydra.run.dir={out_dir}",
                                threads=threads)
            rows.append({**{k: m.get(k) for k in FINAL_KEYS}, "frame": f.index, "time_s": f.time_s,
                         "warm_start": bool(m.get("warm_start")), "folder": folder.name})
            unit = m.get("deflection_unit", unit)
            log_frame(writer, rows[-1], folder, cfg.figures)
            previous = folder / "checkpoint.pt"
    finally:
        writer.close()
        if rows:
            write_series(rows, out_dir, cfg.figures)
    metrics = series_metrics(rows, frames, cfg)
    if unit is not None:
        metrics["deflection_unit"] = unit
    metrics["total_time_s"] = time.perf_counter() - t_start
    metrics["units"] = metric_units(metrics)
    write_json(metrics, out_dir / "metrics.json")
    headline = Headline.of(metrics, "sigma" if unit is not None else "rad")  # metrics.json: sigma where it says so
    print(summary_line(headline, out_dir, f"{len(rows)} frame{'s' * (len(rows) != 1)}, means: "), flush=True)
    return metrics


def frame_volume(folder: Path):
    """A frame's temperature (or sigma where no temperature is inferred), its truth or None, the unit, the box."""
    with np.load(folder / "reconstruction.npz") as z:
        key = "T" if "T" in z else "sigma"
        vol, truth = z[key], (z["T_true"] if "T_true" in z and key == "T" else None)
        box = ProbeBox(vol.shape, float(z["voxel_mm"]))
    return vol, truth, ("K" if key == "T" else "sigma"), box


def log_frame(writer, row: dict, folder: Path, figures: bool = True) -> None:
    """One TensorBoard step per frame (step = frame index): its final metrics and (``figures``) slices, as the
    frame's ``slices.png`` holds them (drawn once: a figure of 16 panels takes 1-2 s)."""
    for k, v in row.items():
        if k not in ("frame", "folder") and isinstance(v, (int, float)) and v is not None:
            writer.add_scalar(f"frame/{k}", float(v), row["frame"])
    if figures and (folder / "slices.png").is_file():
        from matplotlib.image import imread

        writer.add_image("frame/slices", imread(folder / "slices.png"), row["frame"], dataformats="HWC")
    writer.flush()


def write_series(rows: list[dict], out_dir: Path, figures: bool = True) -> None:
    """``sequence.pvd``, ``frames.md``/``.csv`` and (``figures``) ``sequence.png`` of the finished frames."""
    write_pvd(out_dir / "sequence.pvd", [(r["time_s"], f"{r['folder']}/reconstruction.vti") for r in rows])
    table = [{"config": f"frame {r['frame']} (t = {r['time_s']:.4g} s, {'warm' if r['warm_start'] else 'cold'})",
              **r} for r in rows]
    write_tables(table, out_dir, stem="frames", header="Frames of the time series (sequence.pvd opens them in ParaView)")
    if not figures:
        return
    panels = []
    for r in rows:
        vol, truth, unit, box = frame_volume(out_dir / r["folder"])
        panels.append((f"frame {r['frame']}\nt = {1e3 * r['time_s']:.4g} ms", vol, truth))
    save_figure(sequence_figure(panels, box, unit, f"{len(rows)} frames"), out_dir / "sequence.png")


def series_metrics(rows: list[dict], frames: list[Frame], cfg: DictConfig) -> dict:
    """The series' metrics: every frame's row, and the means (errors) or sums (iterations, time) over frames."""
    def mean(k):
        vals = [r[k] for r in rows if r.get(k) is not None]
        if vals and isinstance(vals[0], str):  # a choice per frame (data_term_kept): how often each was made
            return ", ".join(f"{v} in {vals.count(v)} of {len(rows)} frames" for v in sorted(set(vals)))
        if vals and isinstance(vals[0], list):  # an interval per frame: the mean of each end
            return np.mean(np.asarray(vals, dtype=np.float64), axis=0).tolist()
        return float(np.mean(vals)) if vals else None

    m = {k: mean(k) for k in FINAL_KEYS if k not in ("iterations", "wall_time_s")}
    m.update(frames=rows, n_frames=len(frames), frames_finished=len(rows), warm_start=bool(cfg.sequence.warm_start),
             iterations=int(sum(r["iterations"] or 0 for r in rows)),
             wall_time_s=float(sum(r["wall_time_s"] or 0.0 for r in rows)),
             note="errors and ms_per_iteration are means over the frames; iterations and wall_time_s sums")
    return m
