"""Gradient operators: d(sigma)/d(x, y, z) of a field at sample points.

Each operator is ``op(field, positions (S, 3) [mm], *, create_graph: bool, step_mm: float) -> (S, 3)``
in [1/mm]. ``auto`` differentiates the network by autograd (``create_graph=True`` when a loss is trained
on it: second-order graph); ``discrete`` takes central differences with step ``step_mm`` (6 field
evaluations per sample, first-order graph only).
"""
from __future__ import annotations

import torch

from nerif.registry import Registry

GRADIENTS = Registry("gradient operator", package="nerif.renderers")


@GRADIENTS.register("auto")
def autograd_gradient(field, positions: torch.Tensor, *, create_graph: bool, step_mm: float) -> torch.Tensor:
    with torch.enable_grad():
        p = positions.detach().requires_grad_(True)
        sigma = field(p)
        (g,) = torch.autograd.grad(sigma.sum(), p, create_graph=create_graph)
    return g


@GRADIENTS.register("discrete")
def central_difference_gradient(field, positions: torch.Tensor, *, create_graph: bool, step_mm: float) -> torch.Tensor:
    eye = torch.eye(3, dtype=positions.dtype, device=positions.device) * step_mm
    offsets = torch.stack([eye, -eye], 1).reshape(6, 3)  # +x, -x, +y, -y, +z, -z
    sigma = field((positions[:, None, :] + offsets).reshape(-1, 3)).reshape(-1, 3, 2)
    return (sigma[..., 0] - sigma[..., 1]) / (2.0 * step_mm)
