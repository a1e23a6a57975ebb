"""Deflection rendering: ``eps = sum_i grad(sigma)(p_i) dt_i`` along each ray (paraxial, straight rays)."""
from __future__ import annotations

from typing import Mapping, Optional

import torch

from nerif.renderers.gradients import GRADIENTS
from nerif.renderers.samplers import Samples


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
