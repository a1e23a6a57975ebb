"""Voxel forward model: deflections of rays through a voxel field of delta.

The gradient of the field is taken on the grid by central differences (one-sided at the faces, like
MATLAB's and numpy's ``gradient``: a field cut by the box continues smoothly, no jump to ambient is
invented), interpolated trilinearly at the ray samples and integrated along each ray's chord through the
box. For a field that is ambient at the faces, the component along a ray integrates to zero. The map
delta -> deflection is linear; torch autograd gives its exact adjoint.
"""
from __future__ import annotations

import torch

from nerif.geometry import ProbeBox, sample_volume
from nerif.renderers.deflection import integrate
from nerif.renderers.samplers import UniformSampler


def gradient_volume(delta: torch.Tensor, voxel_mm: float) -> torch.Tensor:
    """Central differences inside, one-sided at the faces: (nx, ny, nz) -> (3, nx, ny, nz) [1/mm]."""
    return torch.stack(torch.gradient(delta, spacing=voxel_mm, edge_order=1))


def chord_sampler(box: ProbeBox, step_mm: float | None = None) -> UniformSampler:
    """The voxel forward model's quadrature: midpoint samples along each chord, as many as a step of at most
    ``step_mm`` (default half a voxel) needs over the box diagonal (the longest chord)."""
    step = step_mm or box.voxel_mm / 2
    diag = float((box.extent_mm**2).sum() ** 0.5)
    return UniformSampler(max(2, int(-(-diag // step))), jitter=False)


def voxel_deflection(delta: torch.Tensor, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor,
                     step_mm: float | None = None, chunk: int = 1 << 15) -> torch.Tensor:
    """Thin-ray deflections of a voxel field.

    Args:
        delta: (nx, ny, nz) field (delta or sigma; the result is in the same units per mm of path).
        origins, dirs: (R, 3) ray origins [mm] and unit directions.
        step_mm: longest quadrature step along a ray [mm]; default half a voxel.
        chunk: rays per batch (bounds memory).
    Returns:
        (R, 3) world-frame deflection [rad for delta]; zero for rays that miss the box.
    """
    return line_integral(gradient_volume(delta, box.voxel_mm), box, origins, dirs, step_mm, chunk)


def line_integral(volume: torch.Tensor, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor,
                  step_mm: float | None = None, chunk: int = 1 << 15) -> torch.Tensor:
    """Integrals of a voxel field (C, nx, ny, nz) along thin rays (R, 3), trilinear, with the voxel forward
    model's quadrature (:func:`chord_sampler`): (R, C) [field units x mm]; zero for rays that miss the box."""
    sampler = chord_sampler(box, step_mm)
    out = []
    for i in range(0, len(origins), chunk):
        s = sampler(box, origins[i:i + chunk], dirs[i:i + chunk])
        out.append(integrate(sample_volume(volume, box, s.positions.to(volume.dtype), padding="border"), s))
    return torch.cat(out) if out else volume.new_zeros(0, volume.shape[0])
