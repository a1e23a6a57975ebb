"""Losses: deflection misfit, and the ambient boundary condition that fixes the field's constant."""
from __future__ import annotations

from typing import Mapping, Optional, Sequence

import torch

from nerif.geometry import ProbeBox, box_faces



def deflection_terms(eps: Mapping[str, torch.Tensor], eps_obs: torch.Tensor) -> dict:
    """Operator name -> mean over rays of ``|eps_op - eps_obs|^2``; (R, 3) each, normalised units."""
    return {name: ((e - eps_obs) ** 2).sum(-1).mean() for name, e in eps.items()}


def weighted_sum(terms: Mapping[str, torch.Tensor], weights: Mapping[str, float]) -> torch.Tensor:
    """``sum_op lambda_op * term_op`` over the operators with a positive weight."""
    parts = [w * terms[name] for name, w in weights.items() if w > 0]
    if not parts:
        raise ValueError("every gradient-loss weight is zero: nothing to train on (set grad.weights)")
    return torch.stack(parts).sum()


def deflection_mse(eps: Mapping[str, torch.Tensor], eps_obs: torch.Tensor, weights: Mapping[str, float]) -> torch.Tensor:
    """``sum_op lambda_op * mean over rays |eps_op - eps_obs|^2`` over the operators with a positive weight.

    Args:
        eps: operator name -> (R, 3) rendered deflection (normalised units).
        eps_obs: (R, 3) observed deflection in the same units.
        weights: operator name -> lambda (e.g. lambda_a for ``auto``, lambda_d for ``discrete``).
    """
    return weighted_sum(deflection_terms(eps, eps_obs), weights)


class AmbientBoundary:
    """``weight * mean |sigma|`` at random points on the box faces that lie in ambient gas.

    Deflections see only gradients: a constant added to sigma inside the box changes no ray, so nothing in
    the data fixes the ambient level. BOS tomography closes the problem with a Dirichlet condition, n = n0
    on the boundary; this is its soft form. The L1 norm lets a few points where a flame does touch a face
    stay hot instead of biasing the level.

    Args:
        box: the probe box.
        faces: the ambient faces, e.g. ``("x", "z", "-y")`` for the lateral faces and the bottom of a flame
            burning along y (``x``: both faces of that axis; see :func:`nerif.geometry.box_faces`). Empty: no
            condition.
        weight: loss weight (normalised units, beside the deflection MSE).
        points: face points per iteration.
    """

    def __init__(self, box: ProbeBox, faces: Sequence[str] = ("x",), weight: float = 0.05, points: int = 256):
        self.box, self.faces, self.weight, self.points = box, box_faces(faces), float(weight), int(points)

    @property
    def active(self) -> bool:
        return bool(self.faces) and self.weight > 0 and self.points > 0

    def sample(self, generator: Optional[torch.Generator], device) -> torch.Tensor:
        """(points, 3) points uniform on each ambient face, the faces drawn evenly [mm]."""
        g = torch.rand(self.points, 3, generator=generator, device=device) * 2 - 1
        faces = torch.as_tensor(self.faces, device=device)[
            torch.randint(len(self.faces), (self.points,), generator=generator, device=device)]
        g[torch.arange(self.points, device=device), faces[:, 0]] = faces[:, 1].to(g.dtype)
        return self.box.from_grid(g)

    def __call__(self, field, generator: Optional[torch.Generator] = None) -> torch.Tensor:
        device = next(field.parameters()).device
        return self.weight * field(self.sample(generator, device)).abs().mean()
