"""The neural refractive-index field: encoder + tiny MLP with a bounded output, optionally gated by a 3-D mask;
its moving average, its warm start from a volume, and its prior interval with the checks against it."""
from __future__ import annotations

import logging
import math
from typing import Callable, Optional

import numpy as np
import torch
from torch import nn
from torch.optim.swa_utils import AveragedModel

from nerif.geometry import ProbeBox
from nerif.physics import Ambient
from nerif.resolution import FLAME
from nerif.units import SHARE, declare

log = logging.getLogger(__name__)

declare(box_at_cold_bound=SHARE, flame_at_prior_bound=SHARE)


class NeuralField(nn.Module):
    """sigma(p) = gate(p) * (k tanh(MLP(enc(p))) + c), confined to the prior interval [a, b].

    ``k = (b - a) / 2``, ``c = (a + b) / 2``; the last layer starts with zero weights and bias
    ``atanh(-c / k)`` so the initial field is exactly ambient (sigma = 0) for every encoder.
    Hidden layers: Kaiming-uniform weights (LeakyReLU slope 0.01), zero biases.

    Args:
        encoder: an encoder module (``out_dim`` features).
        box: probe box; positions are world coordinates [mm], normalised by ``box.normalize``.
        hidden: widths of the hidden layers.
        prior: (a, b) with a < 0 < b.
        gate: optional callable (N, 3) [mm] -> (N,) in [0, 1], the 3-D mask.
    """

    def __init__(self, encoder: nn.Module, box: ProbeBox, hidden=(64, 64), prior=(-1.05, 0.05),
                 gate: Optional[Callable[[torch.Tensor], torch.Tensor]] = None):
        super().__init__()
        a, b = float(prior[0]), float(prior[1])
        if not a < 0.0 < b:
            raise ValueError(f"the prior interval [a, b] = [{a}, {b}] must contain the ambient value 0 strictly inside")
        self.encoder, self.box, self.gate = encoder, box, gate
        self.k, self.c = (b - a) / 2, (a + b) / 2
        layers, width = [], encoder.out_dim
        for h in hidden:
            lin = nn.Linear(width, h)
            nn.init.kaiming_uniform_(lin.weight, a=0.01, nonlinearity="leaky_relu")
            nn.init.zeros_(lin.bias)
            layers += [lin, nn.LeakyReLU(0.01, inplace=True)]  # on the product, which its backward does not need
            width = h
        last = nn.Linear(width, 1)
        nn.init.zeros_(last.weight)
        nn.init.constant_(last.bias, math.atanh(-self.c / self.k))
        self.mlp = nn.Sequential(*layers, last)

    @property
    def finest_cell_mm(self) -> float:
        """The field's finest cell [mm]: the longest box edge over the encoder's ``cells_across``; a voxel of the
        probe grid for an encoder that does not declare it (a new encoder still runs to its results)."""
        cells = getattr(self.encoder, "cells_across", None)
        return 2.0 * self.box.scale_mm / float(cells) if cells else float(self.box.voxel_mm)

    def network(self, p: torch.Tensor) -> torch.Tensor:
        """The ungated field, (N, 3) [mm] -> (N,)."""
        return self.k * torch.tanh(self.mlp(self.encoder(self.box.normalize(p)))[:, 0]) + self.c

    def forward(self, p: torch.Tensor) -> torch.Tensor:
        """(N, 3) world points [mm] -> (N,) sigma; the network is not evaluated where the gate is zero."""
        if self.gate is None:
            return self.network(p)
        g = self.gate(p)
        keep = (g > 0).nonzero()[:, 0]
        return p.new_zeros(len(p)).index_put((keep,), self.network(p[keep]) * g[keep])

    def load_checked(self, state: dict) -> None:
        """``load_state_dict``; a state of another field configuration (encoder or field settings) said in one
        sentence."""
        try:
            self.load_state_dict(state)
        except RuntimeError as e:
            raise ValueError("the checkpoint was made with another field configuration (encoder/field settings "
                             f"differ): {str(e).splitlines()[0]}") from None

    @torch.no_grad()
    def on_grid(self, box: ProbeBox, chunk: int = 1 << 18) -> torch.Tensor:
        """sigma at the voxel centres of ``box``, (nx, ny, nz)."""
        dev = next(self.parameters()).device
        pts = torch.as_tensor(box.centres().reshape(-1, 3), dtype=torch.float32, device=dev)
        out = torch.cat([self(pts[i:i + chunk]) for i in range(0, len(pts), chunk)])
        return out.reshape(box.shape)


def perturb_tables(field: NeuralField, share: float, generator: torch.Generator) -> None:
    """Add to each of ``field``'s encoder parameters Gaussian noise of ``share`` times its own RMS (drawn from
    ``generator``), in place: an ensemble's member starts from a perturbed field, and what the data pin down is
    pulled back by its training while what they leave free stays perturbed."""
    with torch.no_grad():
        for p in field.encoder.parameters():
            noise = torch.randn(p.shape, generator=generator, device=p.device, dtype=p.dtype)
            p.add_(noise * (share * p.pow(2).mean().sqrt()))


def fit_to_volume(field: NeuralField, box: ProbeBox, sigma: torch.Tensor, iterations: int, *, lr: float = 5e-3,
                  batch: int = 8192, generator: Optional[torch.Generator] = None) -> float:
    """Regress ``field`` onto a voxel volume (a warm start, e.g. from a fast voxel solver): Adam on the squared
    error at ``batch`` random voxel centres per iteration, a fresh optimiser of its own.

    Args:
        sigma: (nx, ny, nz) sigma at the voxel centres of ``box``, on the field's device.
    Returns:
        the RMS difference over every voxel at the end (sigma units).
    """
    dev = sigma.device
    centres = torch.as_tensor(box.centres().reshape(-1, 3), dtype=torch.float32, device=dev)
    target = sigma.reshape(-1).to(torch.float32)
    opt = torch.optim.Adam(field.parameters(), lr=lr)
    for _ in range(iterations):
        i = torch.randint(len(target), (batch,), device=dev, generator=generator)
        loss = (field(centres[i]) - target[i]).square().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
    with torch.no_grad():
        return float((field.on_grid(box).reshape(-1) - target).square().mean().sqrt())


def averaged_field(field: NeuralField, decay: float, rate: Optional[Callable[[], float]] = None) -> AveragedModel:
    """An exponential moving average of ``field``'s weights (Polyak averaging), updated by
    ``average.update_parameters(field)`` after each optimiser step and evaluated as ``average.module``.

    Each update moves the average towards the new weights by ``1 - d``. Its memory, ``1 / (1 - d)`` steps, is
    ``1 / (1 - decay)`` (50 at 0.98), shortened at the start (``d <= (1 + n) / (10 + n)`` after n updates: the
    first update copies the weights, the next follow the fast early steps) and, with ``rate`` (the learning rate
    now over its peak), in proportion to the rate once it is below half its peak: the jitter the average removes
    scales with the rate, while its lag behind weights that still move does not, so the average ends on the last
    weights as the rate anneals. Training is unchanged. Buffers (hash-level constants) and the 3-D gate are
    copied, not averaged.
    """
    if not 0.0 < decay < 1.0:
        raise ValueError(f"an average's decay must be within (0, 1), got {decay}")

    @torch.no_grad()
    def ema(averaged: list[torch.Tensor], current: list[torch.Tensor], n: torch.Tensor) -> None:
        n = int(n)
        d = min(decay, (1.0 + n) / (10.0 + n))
        if rate is not None:
            d = min(d, max(0.0, 1.0 - (1.0 - decay) / max(min(1.0, 2.0 * rate()), 1e-12)))
        torch._foreach_lerp_(averaged, current, 1.0 - d)

    return AveragedModel(field, multi_avg_fn=ema, use_buffers=False)


DEFAULT_PRIOR = (-1.05, 0.05)  # hot gas in cooler ambient: sigma from -1 (T_max) to slightly above 0


def prior_interval(configured=None, data_prior=None) -> tuple[float, float]:
    """The field's prior interval: ``configured`` (``field.prior``) when set, else the one the data give
    (``data_prior``), else :data:`DEFAULT_PRIOR`."""
    prior = configured if configured is not None else (data_prior or DEFAULT_PRIOR)
    try:
        a, b = (float(x) for x in prior)
    except (TypeError, ValueError):
        a = b = float("nan")
    if not a <= 0.0 <= b or not a < b:
        raise ValueError(f"{'field.prior' if configured is not None else 'the data give the prior'} {list(prior)}: "
                         "an increasing pair [a, b] of sigma with a <= 0 <= b (ambient gas is sigma = 0)")
    return a, b


def bound_words(ambient: Ambient, source: Optional[str]) -> str:
    """What sets the field's hot bound, as a user would edit it (``source``: :func:`prior_source`)."""
    return f"set by {source}" if source else f"set by data.T_max={ambient.T_max:g} K"


def hot_bound_advice(hottest_K: float, ambient: Ambient, prior: tuple[float, float], source: Optional[str]) -> str:
    """The setting to change so that the field can reach ``hottest_K`` [K]: the one that bounds it (``source``:
    :func:`prior_source`; None: the default prior, bounded by ``data.T_max``)."""
    target = float(np.ceil(hottest_K / 50) * 50)
    if source is None:
        return f"set data.T_max={target:.0f} or higher"
    if source == "field.prior":
        a = float(np.floor((ambient.sigma_from_temperature(np.float64(target)) - 0.05) * 100) / 100)
        return f"set field.prior=[{a:g}, {prior[1]:g}] or lower (sigma of {target:.0f} K with a margin)"
    return f"raise the upper temperature of {source} to {target:.0f} K or higher (it bounds the field, not data.T_max)"


def prior_source(configured, data_prior_from: Optional[str]) -> Optional[str]:
    """What sets the field's prior (:func:`prior_interval`), as a user would edit it: ``field.prior`` when set, else
    the data's own setting (``data_prior_from``, e.g. a rig file's ``temperature_range_K``), else None (the
    default interval, scaled by ``data.T_max``)."""
    return "field.prior" if configured is not None else data_prior_from


def check_truth_within(truth_T: Optional[np.ndarray], ambient: Ambient, prior: tuple[float, float],
                       source: Optional[str] = None) -> None:
    """Refuse a known truth (nx, ny, nz) [K] that a field of sigma in ``prior`` cannot represent (hotter than
    the prior's bound allows), in one sentence naming the setting to raise (``source``: what sets the prior,
    :func:`prior_source`). Nothing where no truth is known."""
    if truth_T is None or not ambient.temperature_known:
        return
    sigma = ambient.sigma_from_temperature(truth_T)
    if sigma.max() > prior[1] + 1e-6:  # colder than the cold bound: no T_max helps
        coldest = float(truth_T.min())
        raise ValueError(f"the true field reaches {coldest:.0f} K, colder than ambient ({ambient.T0:g} K) by more than "
                         f"the field can represent (its prior's cold bound sigma = {prior[1]:g}): set the phantom's T0 "
                         f"to its coldest gas, or field.prior=[{prior[0]:g}, {np.ceil(sigma.max() * 100) / 100:g}]")
    if sigma.min() < prior[0] - 1e-6:
        hottest = float(truth_T.max())
        bound = float(ambient.temperature_from_sigma(np.float64(prior[0])))
        raise ValueError(f"the true field reaches {hottest:.0f} K, beyond what the field can represent (up to "
                         f"{bound:.0f} K at the prior's bound sigma = {prior[0]:g}, {bound_words(ambient, source)}): "
                         f"{hot_bound_advice(hottest, ambient, prior, source)}")


def prior_saturation(sigma: np.ndarray, prior: tuple[float, float], ambient: Ambient,
                     truth_T: Optional[np.ndarray] = None, failed: str = "", source: Optional[str] = None) -> dict:
    """What a reconstruction ``sigma`` says about the prior's bounds, for ``metrics.json``: the share of the flame
    (voxels below -:data:`~nerif.resolution.FLAME`) within 1 % of the lower bound (``warnings`` over 1 %: the flame
    may be hotter than ``data.T_max`` lets the field be), and the share of the probe box within 1 % of the upper,
    cold bound (``warnings`` over 5 %: a flame holds no gas much colder than ambient, so a field pressed there was fitted to
    data it cannot explain: deflections of the wrong sign, or a geometry that does not match the images; normal
    runs leave none there, the multicam capture read without its lens model 2 %). With a known truth
    (``truth_T`` [K]) far from the hot bound, a flame at that bound is said to be a fit gone astray instead; so it is
    where the held-out views say the fit failed (``failed``: :meth:`nerif.evaluation.Evaluation.failed`'s sentence): the
    data then do not support a hotter flame, and raising the bound is not the advice."""
    a, b = prior
    flame = sigma < -FLAME
    share = float((sigma[flame] <= a + 0.01 * (b - a)).mean()) if flame.any() else 0.0
    cold = float((sigma >= b - 0.01 * (b - a)).mean()) if sigma.size else 0.0
    out = {"flame_at_prior_bound": share, "box_at_cold_bound": cold}
    warn = []
    if cold > 0.05:
        warn.append(f"{100 * cold:.0f} % of the probe box sits at the coldest value the field can hold (sigma = "
                    f"{b:g}): the data pull the field colder than ambient (deflections of the wrong sign, or a rig "
                    "geometry or calibration that does not match the images)")
    elif share > 0.01 and truth_T is not None and ambient.temperature_known and \
            ambient.sigma_from_temperature(truth_T).min() > a + 0.25 * (b - a):
        warn.append(f"{100 * share:.1f} % of the flame sits at the hottest the field can hold, while the known truth "
                    f"peaks at {float(truth_T.max()):.0f} K, far from it: the fit went astray (lower train.lr), "
                    "rather than a flame hotter than data.T_max")
    elif share > 0.01 and failed:
        warn.append(f"{100 * share:.1f} % of the flame sits at the hottest the field can hold, but the held-out views "
                    "say the fit failed, so the data do not support a hotter flame: raising data.T_max would not help; "
                    "look at the measurement first")
    elif share > 0.01:
        if ambient.temperature_known:
            hottest = float(ambient.temperature_from_sigma(np.float64(a)))
            warn.append(f"{100 * share:.1f} % of the flame sits at the hottest {hottest:.0f} K the field can hold "
                        f"({bound_words(ambient, source)}): it may be hotter; "
                        f"{hot_bound_advice(hottest + 100.0, ambient, prior, source)}")  # room above the bound
        else:
            warn.append(f"{100 * share:.1f} % of the flame sits at the prior's bound sigma = {a:g}: it may be hotter; "
                        "lower the first value of field.prior")
    if warn:
        out["warnings"] = warn
        log.warning("%s", warn[0])
    return out
