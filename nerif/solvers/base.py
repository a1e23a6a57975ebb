"""The solver registry and the iteration loop every solver shares: progress, evaluation cadence, atomic
checkpoints, Ctrl-C, timing, and the errors of a reconstruction against the truth and the held-out views.

A solver is built from its config group like any component (``SOLVERS.build(cfg.solver)``: cheap, it checks its
settings before any data are made), then given the data with :meth:`IterativeSolver.setup` ``(scene, masks)``
and run with :meth:`IterativeSolver.fit`. It subclasses :class:`IterativeSolver` and provides ``setup``,
``step() -> dict`` (one timed iteration, its terms as floats), ``evaluate() -> dict`` (appends to ``history``),
``reconstruction() -> sigma volume``, ``predict(origins, dirs) -> deflections`` (of any rays, for the held-out
views) and ``state_dict`` / ``load_state_dict`` for checkpoints. Every module of :mod:`nerif.solvers` registers
its solvers in :data:`SOLVERS`.
"""
from __future__ import annotations

import logging
import signal
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Mapping, Optional

import numpy as np
import torch

from nerif.evaluation import Evaluation
from nerif.geometry import box_faces
from nerif.export import atomic_save_torch
from nerif.masks.backprojection import ambient_faces
from nerif.registry import Registry
from nerif.units import declare

log = logging.getLogger(__name__)

declare(ms_per_iteration="ms", ms_per_iteration_mean="ms", iterations="iterations", iteration="iterations",
        text=("solver", "encoder", "grad", "data_term", "sampler", "mask", "ambient_faces", "flame_crosses_faces"),
        containers={"history": "(the evaluations during training, each unit by its name here)"})
SOLVERS = Registry("solver", package="nerif.solvers")
_COUNTERS = ("iteration", "history", "train_seconds", "step_times")


def _same(a, b) -> bool:
    """Fingerprint entries equal, numbers to a relative 1e-3."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and abs(a - b) <= 1e-3 * max(abs(a), abs(b))
    return a == b


class DivergenceError(RuntimeError):
    """The loss became NaN or infinite."""


def _kept(checkpoint: Optional[Path]) -> str:
    """What a diverged run leaves: the last checkpoint (the step that diverged is never saved), or none yet."""
    if checkpoint is not None and Path(checkpoint).is_file():
        iteration = torch.load(checkpoint, weights_only=False)["iteration"]
        return f"the checkpoint of iteration {iteration} is kept ({checkpoint})"
    return "no checkpoint had been saved yet"


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, SIGTERM (Slurm preemption, ``timeout``, a container stop) or SIGUSR2 (Slurm's and submitit's
    warning before the time limit) during a run: the work done so far is saved."""

    def __init__(self, signal_name: str = "SIGINT"):
        super().__init__(signal_name)
        self.signal_name = signal_name


CAUGHT_SIGNALS = ("SIGINT", "SIGTERM", "SIGUSR2")


@contextmanager
def stop_signals():
    """Within the block, Ctrl-C (SIGINT), SIGTERM (Slurm preemption, ``timeout``, a container stop) and SIGUSR2
    (Slurm's warning before the time limit) are recorded in the list the block is given, not raised: the block
    checks it between steps and stops there. An exception raised wherever the signal lands can be lost (in a
    finalizer it is ignored, and the run went on). A second signal of a kind acts at once, as without the block
    (Ctrl-C twice: KeyboardInterrupt). A signal ignored on entry stays ignored (as Python leaves SIGINT in a job a
    shell started in the background). Main thread only; the previous handlers are restored after, so that a
    launcher's own SIGUSR2 handler, submitit's requeue, can be given the signal again once the checkpoint is saved."""
    received: list[str] = []
    if threading.current_thread() is not threading.main_thread():
        yield received
        return
    previous: dict = {}

    def handler(signum, frame):
        received.append(signal.Signals(signum).name)
        signal.signal(signum, previous[signum] or signal.SIG_DFL)

    numbers = [getattr(signal, name) for name in CAUGHT_SIGNALS if hasattr(signal, name)]
    previous.update({n: signal.signal(n, handler) for n in numbers if signal.getsignal(n) is not signal.SIG_IGN})
    try:
        yield received
    finally:
        for n, h in previous.items():
            signal.signal(n, h or signal.SIG_DFL)


def check_faces(setting, key: str = "loss.ambient_faces", auto: bool = True) -> None:
    """A list of face names (:func:`nerif.geometry.box_faces`), or ``auto`` where allowed; one sentence otherwise."""
    if auto and setting == "auto":
        return
    if isinstance(setting, str):
        raise ValueError(f"{key} must be {'auto or ' if auto else ''}a list of faces such as [x, -y], got '{setting}'")
    box_faces(setting)


class IterativeSolver:
    """State every solver shares: ``iterations`` to run, ``iteration`` done, ``history`` of evaluations,
    ``train_seconds`` of timed steps and each step's duration.

    Args:
        iterations: iterations to run (an upper bound where the solver can stop early).
        eval_every: iterations between evaluations.
        metrics: ``flame_threshold_K`` (flame region: ``|T_true - T0|`` above it) and ``eval_rays_per_view``
            (fixed rays per view on which errors are followed during the run).
        seed: seeds every random draw of the solver (rays, samples, evaluation subsets).
        label: what the run is called (its folder name), e.g. ``hash-discrete`` or ``cgls-tv``.
    """

    name = "solver"
    starts_from_previous = False  # whether :meth:`start_from` can begin a frame from the previous frame's state
    interval: Optional[tuple] = None  # (a, b) the bounds of the result's sigma, where the solver has a prior

    def __init__(self, *, iterations: int, eval_every: int, metrics: Mapping, seed: int, label: str):
        if iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {iterations}")
        if eval_every < 1:
            raise ValueError(f"evaluations every {eval_every} iterations: it must be at least 1")
        self.iterations, self.eval_every = int(iterations), int(eval_every)
        self.flame_threshold_K = float(metrics["flame_threshold_K"])
        self.eval_rays_per_view = int(metrics["eval_rays_per_view"])
        if self.eval_rays_per_view < 1:
            raise ValueError(f"metrics.eval_rays_per_view must be at least 1, got {self.eval_rays_per_view}")
        self.evaluation: Optional[Evaluation] = None  # until setup
        self.seed, self.label = int(seed), str(label)
        self.scene, self.device = None, torch.device("cpu")  # until setup
        self.iteration = 0
        self.history: list[dict] = []
        self.train_seconds = 0.0
        self.step_times: list[float] = []
        self.labels = {"solver": self.name}  # what this run is, for outputs and tables
        self.report: dict = {}  # what the solver decided from the data, for metrics.json
        self.converged = False  # set by a solver that stops early (its step's "converged" term, or evaluate)

    def setup(self, scene, masks) -> "IterativeSolver":
        """Give the solver its data: the scene (rays, observations, held-out views) and the masks. Subclasses
        build their data-dependent state here, after this base part. Returns the solver."""
        self.scene, self.device = scene, scene.dirs.device
        self.evaluation = Evaluation(scene, self.flame_threshold_K, self.eval_rays_per_view, self.seed)
        return self

    def resolve_ambient_faces(self, setting, masks, min_cover: float, fallback) -> list[str]:
        """The faces held at ambient: ``setting`` (a list), or with ``auto`` every face the flame does not cross,
        ``fallback`` where the visual hull covers every face (:func:`nerif.masks.backprojection.ambient_faces`);
        the decision is logged and reported."""
        faces, crossed = ambient_faces(setting, self.scene, masks, min_cover, fallback)
        self.report.update(ambient_faces=faces, flame_crosses_faces=crossed)
        if setting == "auto" and len(crossed) == 6:
            log.warning("the visual hull covers every face of the probe box (the flame's warm gas reaching every "
                        "face, or masks inflated by noisy or smoothed deflections): sigma = 0 on %s "
                        "(loss.ambient_fallback); widen the probe box where the flame reaches a face, else set "
                        "loss.ambient_faces to the faces known to be ambient", ", ".join(faces))
        if crossed:
            log.info("the flame crosses the probe box at %s (visual hull); ambient faces: %s%s", ", ".join(crossed),
                     ", ".join(faces) or "none", " (auto)" if setting == "auto" else "")
        both = sorted(set(crossed) & set(faces))
        if both and setting != "auto":  # with auto, only the fallback (warned above) holds a crossed face
            log.warning("loss.ambient_faces holds sigma = 0 on %s, which the flame crosses: use "
                        "loss.ambient_faces=auto", ", ".join(both))
        return faces

    def _timed(self, dt: float) -> None:
        self.iteration += 1
        self.train_seconds += dt
        self.step_times.append(dt)

    def saturation(self, sigma: np.ndarray, failed: str = "") -> dict:
        """What a reconstruction ``sigma`` says about the solver's bounds, for ``metrics.json``: a bounded
        solver reports the share of the flame at its bound, and ``warnings`` when that is sizeable (``failed``: the
        held-out views' sentence where they say the fit failed). None here."""
        return {}

    def shakes_px(self) -> Optional[torch.Tensor]:
        """(V, 2) each training view's shake between the exposures [px of the full sensor] as the fit refined it,
        or None where the solver refines none (the measurement stage's stand)."""
        return None

    def reconstruction(self) -> np.ndarray:
        """(nx, ny, nz) sigma on the probe grid: the field as it stands."""
        raise NotImplementedError

    @property
    def cell_mm(self) -> float:
        """The finest cell [mm] the solver's field has: a voxel of the probe grid here (a voxel solver), the
        encoder's finest cell for a neural field; it sets the run's resolution (:mod:`nerif.resolution`)."""
        return float(self.scene.box.voxel_mm)

    def volumes(self) -> dict[str, np.ndarray]:
        """Every volume on the probe grid the solver has to show, each (nx, ny, nz) in the unit of sigma unless its
        name says otherwise: ``sigma`` (:meth:`reconstruction`) here, and what a solver adds; with what its
        uncertainty found (:class:`nerif.solvers.uncertainty.Estimate`), :func:`nerif.results.final_volumes` takes
        them all, and the temperature of ``sigma``."""
        return {"sigma": self.reconstruction()}

    def predict(self, origins: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """Deflections of sigma (R, 3) of rays (R, 3) through the current reconstruction, in the unit of
        ``scene.observed``; only their part perpendicular to the rays when the scene's observations are
        perpendicular-only. What :class:`nerif.evaluation.Evaluation` scores."""
        raise NotImplementedError

    # --- checkpoints ---
    def fingerprint(self) -> dict:
        """What a checkpoint must agree on to be resumed: the solver (:attr:`labels`) and the data it was trained
        on (probe box, ambient gas, views, rays and the RMS of each view's observations, 4 significant digits:
        the same data rendered again, on another device, agree)."""
        s = self.scene
        if s is None:  # not given data (a solver driven without a scene)
            return {"solver": dict(self.labels)}
        obs = s.observed.double()
        rms = [float(f"{obs[s.view_slice(v)].pow(2).mean().sqrt().item():.4g}") for v in range(s.n_views)]
        return {"solver": dict(self.labels), "probe box": [*map(int, s.box.shape), float(s.box.voxel_mm)],
                "ambient": [float(s.ambient.T0), float(s.ambient.n0)], "views": [c.name for c in s.cameras],
                "rays": int(len(s.dirs)), "observations (RMS per view)": rms}

    def state_dict(self) -> dict:
        return {**{k: getattr(self, k) for k in _COUNTERS}, "fingerprint": self.fingerprint()}

    def load_state_dict(self, st: dict) -> None:
        for k in _COUNTERS:
            setattr(self, k, st[k])

    def save(self, path: Path) -> None:
        atomic_save_torch(self.state_dict(), path)

    def load(self, path: Path) -> None:
        """Continue from the checkpoint ``path`` (a ``checkpoint.pt``, or a run folder holding one), refused in one
        sentence when it is not a checkpoint of this solver on these data (:meth:`fingerprint`)."""
        path = Path(path)
        if path.is_dir():
            path = path / "checkpoint.pt"
        if not path.is_file():
            raise FileNotFoundError(f"checkpoint {path} does not exist")
        try:
            st = torch.load(path, map_location=self.device, weights_only=False)
        except Exception as e:  # truncated, or not written by torch.save
            raise ValueError(f"{path} is not a readable checkpoint ({type(e).__name__}: "
                             f"{str(e).splitlines()[0] if str(e) else 'no details'})") from None
        if not isinstance(st, dict) or not all(k in st for k in _COUNTERS):
            raise ValueError(f"{path} is not a nerif checkpoint")
        saved = st.get("fingerprint")
        if saved is None:
            log.warning("%s records nothing about the data it was trained on (made before fingerprints): resuming "
                        "it on trust", path)
        else:
            own = self.fingerprint()
            differ = [k for k in own if not _same(saved.get(k), own[k])]
            if differ:
                k = differ[0]
                raise ValueError(f"{path} was made by another run: its {', '.join(differ)} differ from this one's "
                                 f"({k}: {saved.get(k)} there, {own[k]} here); resume only the same solver on the "
                                 "same data, or start afresh without train.resume")
        self.load_state_dict(st)

    def train(self, stop: Optional[Callable[[], bool]] = None) -> bool:
        """Steps to :attr:`iterations` without evaluations or checkpoints (a clone of a trained field,
        :mod:`nerif.solvers.trained`); ``stop()`` true ends it between steps. Returns whether it ran to the end."""
        while self.iteration < self.iterations:
            if stop is not None and stop():
                return False
            self.step()
        return True

    def start_from(self, path: Path) -> None:
        """Start from the final state of another run on data of the same rig and probe box (the previous frame
        of a sequence): what the solver learnt, with fresh optimisation state and counters. Solvers that can
        override it and set :attr:`starts_from_previous`; here one sentence."""
        raise ValueError(f"solver={self.name} cannot start a frame from the previous one: use "
                         "sequence.warm_start=false")

    def checkpoint(self, path: Path) -> None:
        """Save a checkpoint; where the disk refuses it (full, removed), say so and go on: training, and the
        results written after it, matter more than the checkpoint."""
        try:
            self.save(path)
        except OSError as e:
            log.warning("the checkpoint of iteration %d could not be written to %s (%s): training goes on",
                        self.iteration, path, e.strerror or e)

    # --- loop ---
    def fit(self, *, checkpoint_every: int, checkpoint: Optional[Path] = None,
            on_eval: Optional[Callable[[dict], None]] = None, on_step: Optional[Callable[[int, dict], None]] = None,
            progress: bool = True, checkpoint_every_s: Optional[float] = None,
            resume_hint: Optional[str] = None, threads=None, checkpoint_at_end: bool = True) -> dict:
        """Run to ``iterations``, or until converged (a step's ``converged`` term, or :attr:`converged` set by an
        evaluation); evaluates every :attr:`eval_every` and at the end, checkpoints (atomically)
        every ``checkpoint_every`` iterations, at most ``checkpoint_every_s`` seconds apart, at the end and on
        Ctrl-C, SIGTERM or SIGUSR2 (then raises :class:`Interrupted`, after one line saying how to continue:
        ``resume_hint``, default ``train.resume=<checkpoint>``). An exception from ``step`` leaves the last good
        checkpoint in place. ``threads``: told each step's time (:meth:`nerif.threads.ThreadTuner.after_step`), it
        may change the CPU thread count between steps. ``checkpoint_at_end`` False: the final state is left for the
        caller to save (:meth:`checkpoint`) once it has written the results, which then take a nearly full disk's
        room before the checkpoint does."""
        from tqdm import tqdm

        bar = tqdm(total=self.iterations, initial=self.iteration, disable=not progress, mininterval=2.0,
                   desc=self.name, unit="it", dynamic_ncols=True)
        last = self.history[-1] if self.history else {}
        saved_at = time.monotonic()
        try:
            with stop_signals() as received:
                while self.iteration < self.iterations:
                    terms = self.step()
                    if threads is not None:
                        threads.after_step(self.step_times[-1])
                    bar.update(1)
                    if on_step is not None:
                        on_step(self.iteration, terms)
                    done = self.iteration == self.iterations or terms.get("converged", False)
                    if self.iteration % self.eval_every == 0 or done:
                        last = self.evaluate()
                        if on_eval is not None:
                            on_eval(last)
                        if "temperature_rmse_K" in last:
                            bar.set_postfix(loss=f"{terms['loss']:.3g}", T_rmse=f"{last['temperature_rmse_K']:.1f}K")
                        done = done or self.converged
                    due = self.iteration % checkpoint_every == 0 or done or (
                        checkpoint_every_s is not None and time.monotonic() - saved_at >= checkpoint_every_s)
                    if checkpoint is not None and due and not (done and not checkpoint_at_end):
                        self.checkpoint(checkpoint)
                        saved_at = time.monotonic()
                    if received:
                        raise Interrupted(received[0])
                    if done:
                        break
        except KeyboardInterrupt as e:
            what = e.signal_name if isinstance(e, Interrupted) else "SIGINT"
            if checkpoint is not None and self.iteration > 0:
                self.save(checkpoint)
                log.warning("%s at iteration %d: checkpoint saved to %s (continue with %s)", what, self.iteration,
                            checkpoint, resume_hint or f"train.resume={checkpoint}")
            else:
                log.warning("%s at iteration %d: nothing to save", what, self.iteration)
            raise Interrupted(what) from None
        except DivergenceError as e:
            raise DivergenceError(f"{e.args[0]}; {_kept(checkpoint)}") from None
        finally:
            bar.close()
        return last

    def timing(self) -> dict:
        steps = np.asarray(self.step_times) if self.step_times else np.zeros(1)
        return {"iterations": self.iteration, "ms_per_iteration": float(np.median(steps) * 1e3),
                "ms_per_iteration_mean": float(np.mean(steps) * 1e3)}
