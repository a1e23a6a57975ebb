"""Gradient operators: d(sigma)/d(x, y, z) of a field at sample points.

Each operator is ``op(field, positions (S, 3) [mm], *, create_graph: bool, step_mm: float, across=None)
-> (S, 3)`` in [1/mm]. ``auto`` differentiates the network by autograd (``create_graph=True`` when a loss is
trained on it: second-order graph); ``discrete`` takes central differences with step ``step_mm`` (6 field
evaluations per sample, first-order graph only). ``across`` (S, 3): unit ray directions when only the part of the
gradient perpendicular to them is needed (BOS measures no deflection along a ray); an operator may then return
just that part: ``discrete`` differences along two directions across the ray (4 evaluations instead of 6).
"""
from __future__ import annotations

from typing import Optional

import torch

from nerif.registry import Registry

GRADIENTS = Registry("gradient operator", package="nerif.renderers")


@GRADIENTS.register("auto")
def autograd_gradient(field, positions: torch.Tensor, *, create_graph: bool, step_mm: float,
                      across: Optional[torch.Tensor] = None) -> torch.Tensor:
    with torch.enable_grad():
        p = positions.detach().requires_grad_(True)
        sigma = field(p)
        (g,) = torch.autograd.grad(sigma.sum(), p, create_graph=create_graph)
    return g


def across_basis(d: torch.Tensor) -> torch.Tensor:
    """Two unit vectors perpendicular to each unit direction and to each other: (S, 3) -> (S, 2, 3)."""
    axis = torch.zeros_like(d).scatter_(1, d.abs().argmin(1, keepdim=True), 1.0)  # the axis least along d
    u = torch.nn.functional.normalize(torch.linalg.cross(d, axis), dim=-1)
    return torch.stack([u, torch.linalg.cross(d, u)], 1)


@GRADIENTS.register("discrete")
def central_difference_gradient(field, positions: torch.Tensor, *, create_graph: bool, step_mm: float,
                                across: Optional[torch.Tensor] = None) -> torch.Tensor:
    if across is not None:  # sum_k e_k (sigma(p + h e_k) - sigma(p - h e_k)) / 2h over two e_k across the ray
        e = across_basis(across.to(positions.dtype))  # (S, 2, 3)
        offsets = torch.stack([e, -e], 2) * step_mm  # (S, 2, 2, 3)
        sigma = field((positions[:, None, None, :] + offsets).reshape(-1, 3)).reshape(-1, 2, 2)
        return (((sigma[..., 0] - sigma[..., 1]) / (2.0 * step_mm))[..., None] * e).sum(1)
    eye = torch.eye(3, dtype=positions.dtype, device=positions.device) * step_mm
    offsets = torch.stack([eye, -eye], 1).reshape(6, 3)  # +x, -x, +y, -y, +z, -z
    sigma = field((positions[:, None, :] + offsets).reshape(-1, 3)).reshape(-1, 3, 2)
    return (sigma[..., 0] - sigma[..., 1]) / (2.0 * step_mm)
