"""The iteration loop shared by every solver: progress, evaluation cadence, atomic checkpoints, Ctrl-C, timing.

A solver subclasses :class:`IterativeSolver` and provides ``step() -> dict`` (one timed iteration, its
terms as floats), ``evaluate() -> dict`` (appends to ``history``), ``reconstruction() -> sigma volume`` and
``state_dict`` / ``load_state_dict`` for checkpoints.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import torch

from nerif.export import atomic_save_torch
from nerif.metrics import flame_region, rmse

log = logging.getLogger(__name__)
_COUNTERS = ("iteration", "history", "train_seconds", "step_times")


class IterativeSolver:
    """State every solver shares: ``iterations`` to run, ``iteration`` done, ``history`` of evaluations,
    ``train_seconds`` of timed steps and each step's duration."""

    name = "solver"

    def __init__(self, scene, iterations: int, flame_threshold_K: float = 1.0):
        if iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {iterations}")
        self.scene, self.iterations = scene, int(iterations)
        self.device = scene.dirs.device
        self.flame_threshold_K = flame_threshold_K
        self.iteration = 0
        self.history: list[dict] = []
        self.train_seconds = 0.0
        self.step_times: list[float] = []
        self.labels = {"solver": self.name}  # what this run is, for outputs and tables

    def _timed(self, dt: float) -> None:
        self.iteration += 1
        self.train_seconds += dt
        self.step_times.append(dt)

    def field_errors(self, sigma: np.ndarray) -> dict:
        """Temperature and sigma errors of a sigma volume against the scene's truth (empty without one)."""
        if self.scene.truth_T is None:
            return {}
        amb, Tt = self.scene.ambient, self.scene.truth_T
        T = amb.temperature_from_sigma(sigma)
        return {"temperature_rmse_K": rmse(T, Tt),
                "temperature_rmse_flame_K": rmse(T, Tt, flame_region(Tt, amb.T0, self.flame_threshold_K)),
                "sigma_rmse": rmse(sigma, amb.sigma_from_temperature(Tt))}

    # --- checkpoints ---
    def state_dict(self) -> dict:
        return {k: getattr(self, k) for k in _COUNTERS}

    def load_state_dict(self, st: dict) -> None:
        for k in _COUNTERS:
            setattr(self, k, st[k])

    def save(self, path: Path) -> None:
        atomic_save_torch(self.state_dict(), path)

    def load(self, path: Path) -> None:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"checkpoint {path} does not exist")
        self.load_state_dict(torch.load(path, map_location=self.device, weights_only=False))

    # --- loop ---
    def fit(self, *, eval_every: int, checkpoint_every: int, checkpoint: Optional[Path] = None,
            on_eval: Optional[Callable[[dict], None]] = None, on_step: Optional[Callable[[int, dict], None]] = None,
            progress: bool = True) -> dict:
        """Run to ``iterations``; evaluates every ``eval_every`` and at the end, checkpoints every
        ``checkpoint_every`` (atomically) and on Ctrl-C. An exception from ``step`` leaves the last good
        checkpoint in place."""
        from tqdm import tqdm

        bar = tqdm(total=self.iterations, initial=self.iteration, disable=not progress, mininterval=2.0,
                   desc=self.name, unit="it", dynamic_ncols=True)
        last = self.history[-1] if self.history else {}
        try:
            while self.iteration < self.iterations:
                terms = self.step()
                bar.update(1)
                if on_step is not None:
                    on_step(self.iteration, terms)
                done = self.iteration == self.iterations or terms.get("converged", False)
                if self.iteration % eval_every == 0 or done:
                    last = self.evaluate()
                    if on_eval is not None:
                        on_eval(last)
                    if "temperature_rmse_K" in last:
                        bar.set_postfix(loss=f"{terms['loss']:.3g}", T_rmse=f"{last['temperature_rmse_K']:.1f}K")
                if checkpoint is not None and (self.iteration % checkpoint_every == 0 or done):
                    self.save(checkpoint)
                if done:
                    break
        except KeyboardInterrupt:
            if checkpoint is not None:
                self.save(checkpoint)
                log.warning("interrupted at iteration %d; checkpoint saved to %s", self.iteration, checkpoint)
            raise
        finally:
            bar.close()
        return last

    def timing(self) -> dict:
        steps = np.asarray(self.step_times) if self.step_times else np.zeros(1)
        return {"iterations": self.iteration, "ms_per_iteration": float(np.median(steps) * 1e3),
                "ms_per_iteration_mean": float(np.mean(steps) * 1e3)}
