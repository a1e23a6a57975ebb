"""How the neural solver trains its field: the ``train`` group's settings (:class:`Training`), the optimiser with its
stages' cosine schedules and the weights' average (:class:`Optimisation`), what the steps drew
(:class:`SampleCounts`), and a warm start from a volume (:func:`warm_start`)."""
from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Optional

import torch

from nerif.data.phantoms import read_volume
from nerif.encoders import ENCODERS
from nerif.field import NeuralField, averaged_field, fit_to_volume
from nerif.memory import FLOAT
from nerif.renderers import SAMPLERS
from nerif.solvers.batches import check_views_per_batch
from nerif.solvers.stages import StagePlan
from nerif.units import SHARE, declare

log = logging.getLogger(__name__)

declare(samples_per_second="1/s", samples_per_ray_mean="samples", samples_per_ray_max="samples",
        rays_skipped_fraction=SHARE)


@dataclass(frozen=True)
class Training:
    """The neural solver's ``train`` settings (``conf/config.yaml``), each checked when read (:meth:`read`).

    Attributes:
        rays_per_batch: rays a step draws; ``views_per_batch``: from how many views (a number, or ``all``).
        outside_fraction: share of each view's rays drawn outside its 2-D mask.
        stop_when_converged: stop once the best deflection RMSE on the fixed evaluation rays over the last
            ``stop_patience`` evaluations improves on the best before them by less than this fraction (None: never).
        lr, betas, eps, lr_min: Adam's peak rate, moments and epsilon, and the cosine schedule's floor.
        table_decay: each step multiplies the encoder's parameters by ``1 - lr table_decay`` (AdamW), so that table
            entries no ray constrains fade to zero instead of wandering under Adam's normalised steps.
        ema_decay: evaluations and outputs use an exponential moving average of the trained weights
            (:func:`nerif.field.averaged_field`; 0: the last weights); training itself is unchanged.
        init_volume: a ``reconstruction.npz`` on this probe grid that the field is first fit to, for
            ``init_iterations`` (:func:`warm_start`); None: none.
    """

    rays_per_batch: int
    views_per_batch: object
    outside_fraction: float
    stop_when_converged: Optional[float]
    stop_patience: int
    lr: float
    betas: tuple
    eps: float
    lr_min: float
    table_decay: float
    ema_decay: float
    init_volume: Optional[str]
    init_iterations: int

    @classmethod
    def read(cls, train: Mapping) -> "Training":
        """The settings of the ``train`` group, or one sentence naming the key whose value cannot be used."""
        t = cls(int(train["rays_per_batch"]), train["views_per_batch"], float(train["outside_fraction"]),
                train["stop_when_converged"], int(train["stop_patience"]), train["lr"], tuple(train["betas"]),
                train["eps"], train["lr_min"], float(train["table_decay"]), float(train["ema_decay"]),
                train["init_volume"], int(train["init_iterations"]))
        if t.rays_per_batch < 1:
            raise ValueError(f"rays per batch must be at least 1, got {t.rays_per_batch}")
        check_views_per_batch(t.views_per_batch)
        if t.stop_when_converged is not None and not 0.0 < float(t.stop_when_converged) < 1.0:
            raise ValueError(f"train.stop_when_converged={t.stop_when_converged}: a relative improvement within "
                             "(0, 1), or null")
        if t.stop_patience < 1:
            raise ValueError(f"train.stop_patience={t.stop_patience}: at least 1 evaluation")
        if not 0.0 <= t.outside_fraction < 1.0:
            raise ValueError(f"outside_fraction must be within [0, 1), got {t.outside_fraction}")
        if not 0.0 <= t.ema_decay < 1.0:
            raise ValueError(f"train.ema_decay={t.ema_decay}: a decay within [0, 1) (0: no average)")
        if t.table_decay < 0:
            raise ValueError(f"train.table_decay={t.table_decay}: a decay rate of at least 0")
        if t.init_volume is not None and not Path(t.init_volume).expanduser().is_file():
            raise FileNotFoundError(f"train.init_volume: volume file {t.init_volume} does not exist")
        return t

    def converged(self, rmses: list[float]) -> Optional[bool]:
        """Whether the deflection RMSEs of the evaluations so far (``rmses``, in order) say training has converged;
        None before there are enough of them, or where training never stops early. The best of the last
        ``stop_patience`` against the best before them: one noisy evaluation (Adam early on, one view's batch) does
        not stop a run."""
        if self.stop_when_converged is None or len(rmses) <= self.stop_patience:
            return None
        before, recent = min(rmses[:-self.stop_patience]), min(rmses[-self.stop_patience:])
        return recent > (1.0 - float(self.stop_when_converged)) * before


class Optimisation:
    """AdamW on a field (the encoder's tables with :attr:`Training.table_decay`, the rest without) and on a data
    term's own parameter groups, on the cosine learning-rate schedules of a :class:`StagePlan` from ``iteration``,
    with the average of the field's weights where :attr:`Training.ema_decay` asks for one.

    Args:
        field: the trained field. groups: the data term's parameter groups (``parameter_groups()``).
        settings: the training settings. plan: the stages. iteration: the iteration the plan runs from now.
    """

    def __init__(self, field: NeuralField, groups: list, settings: Training, plan: StagePlan, iteration: int):
        self.field, self.plan, self.lr_min = field, plan, settings.lr_min
        enc = list(field.encoder.parameters())
        rest = [p for p in field.parameters() if all(p is not q for q in enc)]
        groups = [{"params": rest, "weight_decay": 0.0}] + ([{"params": enc, "weight_decay": settings.table_decay}]
                                                            if enc else []) + groups
        device = next(field.parameters()).device
        self.optimizer = torch.optim.AdamW(groups, lr=settings.lr, betas=settings.betas, eps=settings.eps,
                                           fused=device.type == "cuda")
        self.scheduler = plan.cosine(self.optimizer, iteration, self.lr_min)
        decay = settings.ema_decay
        self.average = averaged_field(field, decay, self.rate) if decay > 0 else None

    def step(self, loss: torch.Tensor) -> None:
        """One optimiser step down ``loss``'s gradient, and the schedule's next rate."""
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.scheduler.step()

    def after_step(self, iteration: int) -> None:
        """The average takes in the step's weights; a stage that ends at ``iteration`` (the steps done) and whose
        successor starts a schedule of its own restarts it."""
        if self.average is not None:
            self.average.update_parameters(self.field)
        if self.plan.restarts(iteration):
            self.scheduler = self.plan.cosine(self.optimizer, iteration, self.lr_min)

    def rate(self) -> float:
        """The learning rate of the next step over its peak (``train.lr``), from 1 down to ``lr_min / lr``."""
        return self.optimizer.param_groups[0]["lr"] / self.scheduler.base_lrs[0]

    @property
    def lr(self) -> float:
        """The learning rate of the next step [1/step, of the first parameter group]."""
        return self.optimizer.param_groups[0]["lr"]

    @property
    def estimate(self) -> NeuralField:
        """The field that evaluations and outputs use: the average of the trained weights once a step has updated
        it, else the trained field itself."""
        if self.average is None or int(self.average.n_averaged) == 0:
            return self.field
        return self.average.module

    @staticmethod
    def averaged_weights(st: dict) -> Optional[dict]:
        """The averaged weights a checkpoint ``st`` holds, where it kept an average that a step updated; else None
        (its trained weights are its result)."""
        average = st.get("average")
        if average is None or int(average["n_averaged"]) == 0:
            return None
        return {k[len("module."):]: v for k, v in average.items() if k.startswith("module.")}

    def state_dict(self) -> dict:
        return {"optimizer": self.optimizer.state_dict(), "scheduler": self.scheduler.state_dict(),
                "average": None if self.average is None else self.average.state_dict()}

    def load_state_dict(self, st: dict, iteration: int) -> None:
        """The state :meth:`state_dict` saved at ``iteration``; the schedule re-planned where the plan is longer or
        shorter now (:meth:`StagePlan.replan`)."""
        try:
            self.optimizer.load_state_dict(st["optimizer"])
        except ValueError as e:
            raise ValueError("the checkpoint's optimiser state does not fit this solver (made by a nerif before "
                             f"train.table_decay, or with another encoder): {str(e).splitlines()[0]}") from None
        self.scheduler.load_state_dict(st["scheduler"])
        self.plan.replan(self.scheduler, self.optimizer, iteration)
        if self.average is not None:
            if st.get("average") is not None:
                self.average.load_state_dict(st["average"])
            else:  # a checkpoint without an average: it starts again from the next step's weights
                self.average.n_averaged.zero_()


class SampleCounts:
    """What the steps drew: samples and rays, the most samples on one ray, the rays that had none."""

    KEYS = ("samples_seen", "rays_seen", "samples_max", "rays_skipped")

    def __init__(self):
        self.samples_seen = self.rays_seen = self.samples_max = self.rays_skipped = 0

    def add(self, samples: int, rays: int, most: int, skipped: int) -> None:
        """A step's ``samples`` over ``rays``, ``most`` on one ray, ``skipped`` rays without any."""
        self.samples_seen += samples
        self.rays_seen += rays
        self.samples_max = max(self.samples_max, most)
        self.rays_skipped += skipped

    def figures(self, seconds: float) -> dict:
        """``samples_per_second`` over ``seconds`` of training, ``samples_per_ray_mean``, ``samples_per_ray_max``,
        ``rays_skipped_fraction``."""
        return {"samples_per_second": self.samples_seen / max(seconds, 1e-9),
                "samples_per_ray_mean": self.samples_seen / max(self.rays_seen, 1),
                "samples_per_ray_max": self.samples_max,
                "rays_skipped_fraction": self.rays_skipped / max(self.rays_seen, 1)}

    def state_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.KEYS}

    def load_state_dict(self, st: dict) -> None:
        for k in self.KEYS:
            setattr(self, k, st[k])


def warm_start(field: NeuralField, box, path: str, interval: tuple[float, float], iterations: int,
               generator: torch.Generator) -> float:
    """Fit ``field`` to the sigma volume of ``path`` (a ``reconstruction.npz`` of any solver on ``box``'s probe grid,
    key ``sigma``) for ``iterations`` (:func:`nerif.field.fit_to_volume`), before training on rays; refused in one
    sentence where its grid or its values (``interval``: the field's sigma bounds) do not fit. Returns the RMS
    difference left [sigma]."""
    vol = read_volume(path, "train.init_volume", key="sigma")
    if vol.shape != tuple(box.shape):
        raise ValueError(f"train.init_volume {path}: shape {vol.shape}, but the probe grid is {tuple(box.shape)}")
    a, b = interval
    lo, hi = float(vol.min()), float(vol.max())
    if lo < a - 0.5 * (b - a) or hi > b + 0.5 * (b - a):  # a temperature [K], or another quantity
        what = " (a temperature in kelvin?)" if lo > 100 else ""
        raise ValueError(f"train.init_volume {path} holds values {lo:.4g} to {hi:.4g}{what}, far outside the "
                         f"field's sigma interval [{a:g}, {b:g}]: give a reconstruction.npz of nerif (its sigma "
                         "is read)")
    device = next(field.parameters()).device
    rms = fit_to_volume(field, box, torch.as_tensor(vol, device=device), iterations, generator=generator)
    log.info("warm start: the field fits %s to %.3g (RMS sigma) after %d iterations", path, rms, iterations)
    return rms


def allocations(cfg) -> list[tuple[str, str, float]]:
    """What training a neural field allocates (:mod:`nerif.memory`), for the run's config ``cfg``: its sampler's and
    encoder's own, the MLP (weights, gradients, Adam's moments, the average), and one step's samples, each evaluated
    at its 6 central-difference neighbours and itself with the activations kept for the backward pass."""
    hidden = [float(h) for h in cfg["field"]["hidden"]]
    features = float(ENCODERS.get(cfg["encoder"]["name"]).features(cfg["encoder"]))
    widths = [features] + hidden + [1.0]
    params = sum(a * b + b for a, b in zip(widths[:-1], widths[1:]))
    samples = float(cfg["train"]["rays_per_batch"]) * float(cfg["sampler"]["samples_per_ray"])
    return SAMPLERS.allocations(cfg, "sampler") + [
        ("the MLP (weights, gradients, Adam's moments, the average)", "field.hidden", params * 5 * FLOAT),
        *ENCODERS.allocations(cfg, "encoder"),
        ("one training step's samples", "train.rays_per_batch or sampler.samples_per_ray",
         samples * 7 * (features + sum(hidden)) * 3 * FLOAT)]
