"""One reconstruction from a resolved config (the steady scene, or one frame of a time series): build the parts,
train, write every output of the run."""
from __future__ import annotations

import logging
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Optional

import torch
from omegaconf import DictConfig

from nerif.configs import group
from nerif.data import DATASETS
from nerif.data.diagnostics import check_sign, ill_posed, missing_wedge
from nerif.export import write_json
from nerif.io.headline import Headline, summary_line
from nerif.io.outputs import (RESULTS, volume_slices, write_figures, write_masks, write_rig, write_sensing,
                              write_volumes)
from nerif.masks import MASKS
from nerif.results import final_volumes, results
from nerif.sensing.measurement import CAUSES
from nerif.solvers import SOLVERS, Interrupted
from nerif.solvers.base import stop_signals
from nerif.solvers.uncertainty import UNCERTAINTY, Estimate
from nerif.units import declare, metric_units, stage_key

log = logging.getLogger(__name__)

declare(text=("device", "warnings"))
_PACKAGE = Path(__file__).resolve().parent  # nerif's own code, whose Python warnings a run records


def resuming(setting) -> bool:
    """Whether a run continues from its own folder: ``train.resume=auto``, or a requeued Slurm job
    (``SLURM_RESTART_COUNT`` above 0: a preempted or timed-out job of a multirun through submitit) without an
    explicit checkpoint."""
    return setting == "auto" or (setting is None and int(os.environ.get("SLURM_RESTART_COUNT", "0") or 0) > 0)


def checkpoint_to_resume(setting, own: Path) -> Optional[Path]:
    """The checkpoint a run continues from: ``train.resume`` when it is a path; where :func:`resuming`, the run
    folder's own ``checkpoint.pt`` when there is one; else none."""
    if resuming(setting):
        return own if own.is_file() else None
    return Path(setting) if setting else None


class WarningRecords(logging.Handler):
    """Every warning nerif logs while installed (on the ``nerif`` logger), and every Python warning nerif's own code
    raises (``warnings.warn``, logged on it), for ``metrics.json`` and the summary line: what the log says, a run's
    results say too."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []
        self._show = None

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())

    def _show_warning(self, message, category, filename, lineno, file=None, line=None) -> None:
        if Path(filename).resolve().is_relative_to(_PACKAGE):
            logging.getLogger("nerif").warning("%s", message)
        else:
            self._show(message, category, filename, lineno, file, line)

    def __enter__(self) -> "WarningRecords":
        logging.getLogger("nerif").addHandler(self)
        self._show, warnings.showwarning = warnings.showwarning, self._show_warning
        return self

    def __exit__(self, *exc) -> None:
        warnings.showwarning = self._show
        logging.getLogger("nerif").removeHandler(self)


def peak_memory_gib() -> Optional[float]:
    """The process's peak resident memory so far [GiB] (the host's, with everything it read), None where the system
    does not say (Windows)."""
    try:
        import resource
    except ImportError:
        return None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**30 if sys.platform == "darwin" else peak / 2**20  # bytes on macOS, KiB on Linux


def reconstruct(cfg: DictConfig, out_dir: Path, device: torch.device, frame: Optional[int] = None,
                start_from: Optional[Path] = None, t_start: Optional[float] = None, about: Optional[dict] = None,
                resume_hint: Optional[str] = None, threads=None) -> dict:
    """One reconstruction (of ``frame`` of a time series, or of the steady scene) into ``out_dir``: build the
    parts, train (from the state of ``start_from``, a checkpoint of the previous frame, unless the run resumes
    its own), write every output (``about``: entries added to its ``metrics.json``; its ``warnings``, those given
    before, lead the run's). Returns the final metrics.
    ``resume_hint``: how to continue after an interruption (default: from this run's checkpoint). ``threads``: a
    :class:`nerif.threads.ThreadTuner` that times the training steps to keep the fastest CPU thread count."""
    with WarningRecords() as records:
        return _reconstruct(cfg, out_dir, device, records, frame=frame, start_from=start_from, t_start=t_start,
                            about=about, resume_hint=resume_hint, threads=threads)


class Board:
    """A run's TensorBoard (``out_dir/tensorboard``): the loss terms every 10 steps, each evaluation's figures, the
    slices every ``image_every`` iterations and the final slices and profiles; the losses kept for ``curves.png``."""

    def __init__(self, out_dir: Path, solver, scene, image_every: int):
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(out_dir / "tensorboard"))
        self.solver, self.scene, self.image_every = solver, scene, image_every
        self.losses: list[tuple[int, dict]] = []

    def on_step(self, it: int, terms: dict) -> None:
        self.losses.append((it, terms))
        if it % 10 == 0:
            for k, v in terms.items():
                self.writer.add_scalar(f"train/{k}", v, it)

    def on_eval(self, m: dict) -> None:
        it = m["iteration"]
        for k, v in m.items():
            if k != "iteration" and isinstance(v, (int, float)):  # None: not defined here (no flame)
                self.writer.add_scalar(f"eval/{k}", v, it)
        if it % self.image_every == 0 and it < self.solver.iterations:  # the final state's: written with the results
            self.writer.add_figure("slices", volume_slices(self.solver.reconstruction(), self.scene,
                                                           f"iteration {it}"), it)
        self.writer.flush()

    def show(self, name: str, png: bytes) -> None:
        """The final slices and profiles in TensorBoard too, as their files hold them (``png``: the PNG's bytes)."""
        import io

        from matplotlib.image import imread

        self.writer.add_image(name, imread(io.BytesIO(png), format="png"), self.solver.iteration, dataformats="HWC")

    def close(self) -> None:
        self.writer.close()


def _prepare(cfg: DictConfig, out_dir: Path, device: torch.device, frame: Optional[int]) -> tuple:
    """Every part of a run, each checked before any training (the solver its settings before any data are made),
    and the masks and the sensing record written: (solver set up, uncertainty, scene, the rig's warnings)."""
    solver = SOLVERS.build(group(cfg, "solver"))
    uncertainty = UNCERTAINTY.build(group(cfg, "uncertainty"))
    extra = {} if frame is None else {"frame": frame}
    scene = DATASETS.build(group(cfg, "data"), device=str(device), **extra)
    masks = MASKS.build(group(cfg, "mask"), scene=scene)
    solver.setup(scene, masks)  # checks a known truth against the prior first
    uncertainty.check(solver)
    rig_warnings = check_sign(scene, cfg.field.prior) + (ill_posed(scene) or missing_wedge(scene))
    write_masks(masks, scene, out_dir, cfg.figures)
    write_sensing(scene, out_dir, CAUSES, cfg.data.get("cache_dir"), cfg.figures)
    return solver, uncertainty, scene, rig_warnings


def _start(solver, resume_setting, checkpoint: Path, start_from: Optional[Path]) -> None:
    """The solver's state to train on from: its own checkpoint where the run resumes (:func:`checkpoint_to_resume`),
    else the previous frame's (``start_from``), else as set up."""
    resume = checkpoint_to_resume(resume_setting, checkpoint)
    if resume is not None:
        solver.load(resume)
        log.info("resumed from %s at iteration %d", resume, solver.iteration)
    elif start_from is not None:
        solver.start_from(start_from)
        log.info("warm start from %s", start_from)


def _train(solver, uncertainty, board: Board, tc, checkpoint: Path, resume_hint,
           threads) -> tuple[list[str], Estimate]:
    """Training (checkpoints on the way, not at the end), then the uncertainty; returns the signals received during
    the uncertainty (which end it, not the results) and what the uncertainty found."""
    try:
        solver.fit(checkpoint_every=tc.checkpoint_every, checkpoint_every_s=tc.checkpoint_every_s,
                   checkpoint=checkpoint, on_eval=board.on_eval, on_step=board.on_step, progress=tc.progress,
                   resume_hint=resume_hint, threads=threads, checkpoint_at_end=False)
        with stop_signals() as received:  # a signal ends the uncertainty, not the results
            estimated = uncertainty(solver, stop=lambda: bool(received))
        if received:
            log.warning("%s while estimating the uncertainty: the results are written without it", received[0])
    except BaseException:
        board.close()
        raise
    return received, estimated


def _write(solver, estimate: Estimate, scene, out_dir: Path, board: Board, cfg: DictConfig, device: torch.device,
           rig_warnings: list[str], records: WarningRecords, about: dict, times: dict, threads) -> dict:
    """Every result of ``solver`` and what its uncertainty found (``estimate``), and ``metrics.json`` (its
    ``warnings``: those given before, the rig's, the results', then every one logged during the run, ``records``;
    ``times``: ``setup_time_s``, and ``t_start`` for the total); where the disk refuses them, one sentence saying what
    is there and what is not, the final state checkpointed where it still fits."""
    checkpoint = out_dir / "checkpoint.pt"
    try:
        try:
            volumes = final_volumes(solver, scene, estimate)
            write_volumes(volumes, scene, out_dir)  # first: what the run made is kept whatever comes after
            found = results(solver, scene, volumes, estimate, flame_above_K=cfg.metrics.flame_above_K,
                            figures=cfg.figures)
            if cfg.figures:
                label = " + ".join(str(v) for k, v in solver.labels.items() if k != "lam")
                write_figures(found, scene, out_dir, solver.history, board.losses,
                              f"{label}, {solver.iteration} iterations",
                              solver.report.get(stage_key("images", "from_iteration")), show=board.show)
            metrics = found.metrics
        finally:
            board.close()
        about = dict(about or {})
        said = about.pop("warnings", []) + rig_warnings + metrics.get("warnings", []) + records.messages
        metrics["warnings"] = list(dict.fromkeys(said))
        metrics.update(setup_time_s=times["setup_time_s"], cpu_threads=torch.get_num_threads(),
                       device=str(device) if device.type == "cpu" else torch.cuda.get_device_name(device))
        metrics.update(threads.report() if threads is not None else {})
        if device.type == "cuda":
            metrics["gpu_peak_memory_gib"] = torch.cuda.max_memory_allocated(device) / 2**30
        metrics["peak_memory_gib"] = peak_memory_gib()
        metrics["total_time_s"] = time.perf_counter() - times["t_start"]
        metrics.update(about)
        metrics["units"] = metric_units(metrics)
        write_json(metrics, out_dir / "metrics.json")
    except OSError as e:  # a full disk: one sentence saying what is there and what is not
        solver.checkpoint(checkpoint)  # the final state where it still fits, for a resumed run to write them from
        saved = sorted(p.name for p in out_dir.iterdir() if not p.name.startswith("."))
        missing = [f for f in RESULTS if f not in saved and (cfg.figures or not f.endswith(".png"))]
        raise ValueError(f"writing the results to {out_dir} failed ({e.strerror or e}); it holds "
                         f"{', '.join(saved) or 'nothing'}, not {', '.join(missing)}: free some space and write "
                         "them again with train.resume=auto") from None
    return metrics


def _reconstruct(cfg: DictConfig, out_dir: Path, device: torch.device, records: WarningRecords, *, frame, start_from,
                 t_start, about, resume_hint, threads) -> dict:
    """:func:`reconstruct`, with the warnings logged meanwhile in ``records``."""
    t_start = time.perf_counter() if t_start is None else t_start
    torch.manual_seed(cfg.seed)
    solver, uncertainty, scene, rig_warnings = _prepare(cfg, out_dir, device, frame)
    if start_from is None and cfg.figures:  # a series' later frames share the first's rig (a figure costs a second)
        write_rig(scene, out_dir)
    checkpoint = out_dir / "checkpoint.pt"
    _start(solver, cfg.train.resume, checkpoint, start_from)
    setup_s = time.perf_counter() - t_start
    board = Board(out_dir, solver, scene, cfg.train.image_every)
    log.info("%s: %d views, %d rays; %s, device %s", cfg.data.name, scene.n_views, len(scene.dirs),
             ", ".join(f"{k} {v}" for k, v in solver.labels.items()), device)
    received, estimate = _train(solver, uncertainty, board, cfg.train, checkpoint, resume_hint, threads)
    metrics = _write(solver, estimate, scene, out_dir, board, cfg, device, rig_warnings, records, about,
                     {"setup_time_s": setup_s, "t_start": t_start}, threads)
    solver.checkpoint(checkpoint)  # after the results: on a nearly full disk, they take the room first
    print(summary_line(Headline.of(metrics, scene.ambient.deflection_unit), out_dir), flush=True)
    if received:
        raise Interrupted(received[0])
    return metrics
