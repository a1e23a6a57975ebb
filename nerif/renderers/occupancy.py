"""Occupancy-grid sampling: skip samples in cells where the field is ambient.

One grid of ``resolution^3`` cells over the probe box. (The paper's cascades ``1 + ceil(log2(bound))``
cover a scene of half-size ``bound`` in network units; the probe box is normalised to ``bound <= 1``,
so one cascade covers every sample.) Each cell keeps ``density = max(decay * density, |sigma(q)|)`` at a
jittered point q inside it; cells with ``density > threshold`` are occupied, stored as a bitfield.
Every cell is occupied until the first update after ``warmup`` iterations, so a field that is still
ambient is not lost. Updates every ``update_every`` iterations: all cells for the first ``full_updates``
updates, then a random ``subset_fraction`` of them.
"""
from __future__ import annotations

from typing import Callable, Optional

import torch

from nerif.renderers.samplers import SAMPLERS, Samples, UniformSampler


def pack_bits(occupied: torch.Tensor) -> torch.Tensor:
    """(N,) bool, N a multiple of 8 -> (N / 8,) uint8 bitfield (bit i of byte j is cell 8 j + i)."""
    weights = (2 ** torch.arange(8, device=occupied.device)).to(torch.uint8)
    return (occupied.reshape(-1, 8).to(torch.uint8) * weights).sum(-1, dtype=torch.uint8)


def unpack_bits(bits: torch.Tensor) -> torch.Tensor:
    """(M,) uint8 -> (8 M,) bool."""
    return ((bits[:, None] >> torch.arange(8, device=bits.device).to(torch.uint8)) & 1).reshape(-1).bool()


@SAMPLERS.register("occupancy")
class OccupancySampler(UniformSampler):
    """The uniform sampler's samples (same positions, same fixed step per ray), minus those in empty cells: an
    ``nn.Module`` whose grid is in buffers (as nerfacc's ``OccGridEstimator``), updated through a callback that
    evaluates the field.

    Args:
        samples_per_ray, jitter: as :class:`UniformSampler`.
        resolution: cells per axis of the grid (paper: 128).
        decay: EMA decay of the cell densities (paper: 0.95).
        threshold: occupancy threshold on |sigma| (paper: 1e-5).
        update_every: iterations between updates (paper: 16).
        warmup: iterations before the first update.
        full_updates: updates that visit every cell before visiting a random subset.
        subset_fraction: share of cells visited by a later update.
    """

    @staticmethod
    def allocations(cfg) -> list[tuple[str, str, float]]:
        """The grid's densities, their update and its bits (:mod:`nerif.memory`)."""
        return [("the occupancy grid", "field.occupancy_resolution", float(cfg["sampler"]["resolution"]) ** 3 * 3 * 4)]

    def __init__(self, samples_per_ray: int = 32, jitter: bool = True, resolution: int = 64, decay: float = 0.95,
                 threshold: float = 1e-5, update_every: int = 16, warmup: int = 64, full_updates: int = 4,
                 subset_fraction: float = 0.125):
        super().__init__(samples_per_ray, jitter)
        if resolution < 2 or resolution**3 % 8:
            raise ValueError(f"occupancy grid resolution must be an even number >= 2, got {resolution}")
        self.resolution, self.decay, self.threshold = int(resolution), float(decay), float(threshold)
        self.update_every, self.warmup, self.full_updates = int(update_every), int(warmup), int(full_updates)
        self.subset_fraction = float(subset_fraction)
        n = self.resolution**3
        # every cell occupied until updated: density +inf means never visited
        self.register_buffer("density", torch.full((n,), float("inf")))  # (R^3,) float
        self.register_buffer("bits", pack_bits(torch.ones(n, dtype=torch.bool)))  # (R^3 / 8,) uint8
        self.register_buffer("updates", torch.zeros((), dtype=torch.long))  # updates made

    # --- grid ---
    def cell_index(self, box, p: torch.Tensor) -> torch.Tensor:
        """(N, 3) [mm] -> (N,) flat cell index ``(i R + j) R + k`` of cell (i, j, k), clamped to the grid."""
        u = (box.to_grid(p) + 1) * 0.5 * self.resolution
        i = u.floor().long().clamp(0, self.resolution - 1)
        return (i[:, 0] * self.resolution + i[:, 1]) * self.resolution + i[:, 2]

    def occupied(self, box, p: torch.Tensor) -> torch.Tensor:
        """(N, 3) [mm] -> (N,) bool."""
        idx = self.cell_index(box, p)
        return ((self.bits[idx >> 3] >> (idx & 7).to(torch.uint8)) & 1).bool()

    @torch.no_grad()
    def update(self, box, occ_eval_fn: Callable[[torch.Tensor], torch.Tensor], iteration: int,
               generator: Optional[torch.Generator] = None) -> None:
        """Visit the cells due at ``iteration``: ``density = max(decay density, occ_eval_fn(q))`` at a jittered
        point q of each; ``occ_eval_fn``: (N, 3) [mm] -> (N,) |sigma|."""
        if iteration < self.warmup or (iteration - self.warmup) % self.update_every:
            return
        device = self.density.device
        R, n = self.resolution, self.resolution**3
        if int(self.updates) < self.full_updates:
            cells = torch.arange(n, device=device)
        else:
            cells = torch.randperm(n, generator=generator, device=device)[: max(1, int(self.subset_fraction * n))]
        ijk = torch.stack([cells // (R * R), (cells // R) % R, cells % R], -1).float()
        u = (ijk + torch.rand(len(cells), 3, generator=generator, device=device)) / R  # jittered, in [0, 1)
        p = box.from_grid(u * 2 - 1)
        value = torch.cat([occ_eval_fn(p[i:i + (1 << 18)]) for i in range(0, len(p), 1 << 18)])
        old = self.density[cells]
        old = torch.where(torch.isinf(old), torch.zeros_like(old), old)  # first visit: no history
        self.density[cells] = torch.maximum(old * self.decay, value.float())
        self.bits.copy_(pack_bits(self.density > self.threshold))
        self.updates += 1

    # --- sampling ---
    def forward(self, box, origins: torch.Tensor, dirs: torch.Tensor,
                generator: Optional[torch.Generator] = None) -> Samples:
        s = super().forward(box, origins, dirs, generator)
        keep = self.occupied(box, s.positions)
        return Samples(s.positions[keep], s.dt[keep], s.ray_index[keep], s.n_rays)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs):
        key = prefix + "updates"
        if key in state_dict and not torch.is_tensor(state_dict[key]):  # a checkpoint from before the buffers
            state_dict[key] = torch.tensor(int(state_dict[key]))
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
