"""Deflection rendering: ``eps = sum_i grad(sigma)(p_i) dt_i`` along each ray (paraxial, straight rays)."""
from __future__ import annotations

from typing import Mapping, Optional

import torch

from nerif.renderers.gradients import GRADIENTS
from nerif.renderers.samplers import Samples, UniformSampler
from nerif.units import declare
declare(field_evaluations_per_sample="evaluations")


def integrate(values: torch.Tensor, samples: Samples) -> torch.Tensor:
    """Segment sum of per-sample values weighted by dt: (S, C) -> (n_rays, C)."""
    out = values.new_zeros(samples.n_rays, values.shape[-1])
    return out.index_add(0, samples.ray_index, values * samples.dt[:, None].to(values.dtype))


def perpendicular(eps: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """The part of deflections (R, 3) perpendicular to their rays (R, 3): what a BOS camera can measure.

    The component along a straight ray integrates to sigma(exit) - sigma(entry): zero for a field that is
    ambient on the box faces, but not for one cut by the box (Phantom 5 is hot on its y and z faces), and no
    background displacement shows it."""
    return eps - (eps * dirs).sum(-1, keepdim=True) * dirs


def render_deflections(field, samples: Samples, operators: Mapping[str, bool], step_mm: float,
                       dirs: Optional[torch.Tensor] = None, stencil: str = "axes") -> dict:
    """Deflections of the field along packed samples for each named gradient operator.

    Args:
        field: callable (S, 3) [mm] -> (S,) sigma.
        operators: operator name -> whether a loss is trained on it (builds the graph it needs:
            second-order for ``auto``); an untrained operator is evaluated without any parameter graph.
        step_mm: central-difference step for ``discrete``.
        dirs: (n_rays, 3) ray directions: when given, only the measurable part :func:`perpendicular` to them.
        stencil: ``axes`` (central differences along x, y, z), or ``across``: with ``dirs``, along two directions
            across each ray, skipping the along-ray derivative (4 evaluations per sample instead of 6).
    Returns:
        name -> (n_rays, 3) deflection of sigma (dimensionless; multiply by delta_thre for radians).
    """
    out = {}
    pos = samples.positions
    across = dirs.to(pos.dtype)[samples.ray_index] if dirs is not None and stencil == "across" else None
    for name, trained in operators.items():
        op = GRADIENTS.get(name)
        if trained:
            g = op(field, pos, create_graph=True, step_mm=step_mm, across=across)
        else:
            g = op(field, pos, create_graph=False, step_mm=step_mm, across=across).detach()
        eps = integrate(g, samples)
        out[name] = eps if dirs is None else perpendicular(eps, dirs.to(eps.dtype))
    return out


class DeflectionRenderer:
    """How a neural field's deflections are rendered: by which gradient operators (``weights``: name -> its loss
    weight; an operator of weight 0 is not trained on), with which central-difference ``step_mm`` and ``stencil``,
    and, where only the part perpendicular to the rays is measured (``perpendicular_only``), projected; for training
    (:meth:`train`, on a step's packed samples, with the graph the trained operators need) and for evaluation
    (:meth:`evaluate`, on any rays, ``samples_per_ray`` uniform samples without jitter, no graph, bounded memory)."""

    def __init__(self, weights: Mapping[str, float], stencil: str, step_mm: float, perpendicular_only: bool,
                 samples_per_ray: int):
        self.weights, self.stencil, self.step_mm = dict(weights), stencil, float(step_mm)
        self.perpendicular_only = bool(perpendicular_only)
        self.sampler = UniformSampler(samples_per_ray, jitter=False)

    @staticmethod
    def check(weights: Mapping[str, float], stencil: str) -> None:
        """The ``grad`` group's ``weights`` and ``stencil``, or one sentence naming what cannot be used."""
        if stencil not in ("axes", "across"):
            raise ValueError(f"grad.stencil must be 'axes' or 'across', got '{stencil}'")
        if not any(w > 0 for w in weights.values()):
            raise ValueError("every gradient-loss weight is zero: nothing to train on (set grad.weights)")

    @property
    def trained(self) -> dict:
        """The operators trained on (weight above 0), each with its graph."""
        return {name: True for name, w in self.weights.items() if w > 0}

    @property
    def fitted_operator(self) -> str:
        """The gradient operator whose deflections are reported: discrete when it is trained on, else the first
        trained one."""
        return "discrete" if "discrete" in self.trained else next(iter(self.trained))

    @property
    def evaluations_per_sample(self) -> int:
        """Field evaluations per sample of a training step: 1 for ``auto`` (plus its double backward), 6 for
        ``discrete`` (4 with ``stencil=across`` on perpendicular-only data), summed over the trained operators."""
        cost = {"auto": 1, "discrete": 4 if self.stencil == "across" and self.perpendicular_only else 6}
        return sum(cost[n] for n in self.trained)

    def _dirs(self, d: torch.Tensor) -> Optional[torch.Tensor]:
        return d if self.perpendicular_only else None

    def train(self, field, samples: Samples, dirs: torch.Tensor) -> dict:
        """(n_rays, 3) deflections of a step's rays (``dirs``) by each trained operator, with their graphs."""
        return render_deflections(field, samples, self.trained, self.step_mm, dirs=self._dirs(dirs),
                                  stencil=self.stencil)

    def evaluate(self, field, box, o: torch.Tensor, d: torch.Tensor, operators=("auto", "discrete")) -> dict:
        """Deflections of sigma of rays (R, 3) from ``o`` along ``d`` through ``box`` by each operator, without any
        parameter graph, in passes of at most 2^18 samples."""
        out = {n: [] for n in operators}
        chunk = max(1, min(4096, (1 << 18) // self.sampler.samples_per_ray))  # rays per pass: bounded memory
        for i in range(0, len(d), chunk):
            s = self.sampler(box, o[i:i + chunk], d[i:i + chunk])
            eps = render_deflections(field, s, {n: False for n in operators}, self.step_mm,
                                     dirs=self._dirs(d[i:i + chunk]), stencil=self.stencil)
            for n in operators:
                out[n].append(eps[n].detach())
        return {n: torch.cat(v) if v else d.new_zeros(0, 3) for n, v in out.items()}
