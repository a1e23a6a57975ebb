"""Samplers: turn rays into packed samples inside the probe box.

Samples are packed (ragged): ``positions (S, 3)``, step lengths ``dt (S,)`` and ``ray_index (S,)``, so a
sampler may emit any number of samples per ray and rays that miss the box emit none.

A sampler is an ``nn.Module`` (its state, if any, in buffers: ``.to(device)`` and checkpoints as any module),
called as ``sampler(box, origins, dirs, generator)``, and told before every training iteration
``sampler.update(box, occ_eval_fn, iteration, generator)``, with ``occ_eval_fn(positions (N, 3) [mm]) -> (N,)``
the field's occupancy value ``|sigma|`` there, so that a sampler that skips empty space can follow the field.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import torch
from torch import nn

from nerif.geometry import ProbeBox
from nerif.registry import Registry

SAMPLERS = Registry("sampler", package="nerif.renderers")


@dataclass
class Samples:
    """Packed samples along a batch of rays.

    Attributes:
        positions: (S, 3) [mm]. dt: (S,) quadrature weight (segment length) [mm].
        ray_index: (S,) int64 index of each sample's ray in [0, n_rays). n_rays: number of rays.
    """

    positions: torch.Tensor
    dt: torch.Tensor
    ray_index: torch.Tensor
    n_rays: int

    @property
    def per_ray(self) -> torch.Tensor:
        """(n_rays,) number of samples of each ray."""
        return torch.bincount(self.ray_index, minlength=self.n_rays)


@SAMPLERS.register("uniform")
class UniformSampler(nn.Module):
    """K samples per ray, evenly over its chord through the box, shifted by one random offset per ray.

    Sample k of a ray with chord [t0, t1] sits at ``t0 + (k + u) (t1 - t0) / K`` with ``u ~ U(0, 1)``
    (``u = 1/2``, the midpoint rule, when ``jitter`` is off or no generator is given).
    """

    def __init__(self, samples_per_ray: int = 32, jitter: bool = True):
        super().__init__()
        if samples_per_ray < 2:
            raise ValueError(f"samples per ray K must be at least 2, got {samples_per_ray}")
        self.samples_per_ray, self.jitter = int(samples_per_ray), jitter

    def update(self, box: ProbeBox, occ_eval_fn: Callable[[torch.Tensor], torch.Tensor], iteration: int,
               generator: Optional[torch.Generator] = None) -> None:
        """Called before every training iteration; the uniform sampler keeps no state."""

    def forward(self, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor,
                 generator: Optional[torch.Generator] = None) -> Samples:
        """origins, dirs: (R, 3) -> Samples with K samples per ray that hits the box."""
        K = self.samples_per_ray
        t0, t1, hit = box.intersect(origins, dirs)
        rays = hit.nonzero()[:, 0]
        t0, length = t0[rays], (t1 - t0)[rays]
        if self.jitter and generator is not None:
            u = torch.rand(len(rays), 1, generator=generator, device=generator.device).to(dirs.dtype)
        else:
            u = torch.full((len(rays), 1), 0.5, dtype=dirs.dtype, device=dirs.device)
        dt = length / K
        t = t0[:, None] + (torch.arange(K, dtype=dirs.dtype, device=dirs.device) + u) * dt[:, None]  # (H, K)
        pos = origins[rays, None, :] + t[..., None] * dirs[rays, None, :]
        return Samples(pos.reshape(-1, 3), dt[:, None].expand(-1, K).reshape(-1),
                       rays[:, None].expand(-1, K).reshape(-1), len(origins))
