"""Voxel projectors: ``Ax`` (field on the probe grid -> ray deflections) and its exact adjoint ``Atb``.

The forward map is the voxel forward model of :mod:`nerif.renderers.voxel`: grid gradient G, trilinear
interpolation at the ray samples and quadrature along the chord, ``A = S G``. Two implementations, registered
in :data:`PROJECTORS`:

- ``matrix_free``: recomputes the samples per ray chunk; the adjoint is the vector-Jacobian product (exact for
  a linear map). Memory is bounded by ``chunk`` rays; nothing is stored.
- ``sparse``: stores S (rays x voxels, the same weights summed per ray and voxel) as a CSR matrix and its
  transpose, built once chunk by chunk; ``Ax = S (G x)``, ``Atb = G^T (S^T y)``. Several times faster per
  product where the matrix fits in memory.
"""
from __future__ import annotations

import warnings
from typing import Optional

import torch

from nerif.geometry import ProbeBox
from nerif.registry import Registry
from nerif.renderers.voxel import chord_sampler, gradient_volume, voxel_deflection

PROJECTORS = Registry("projector", package="nerif.solvers.voxel")


def adjoint(op, y: torch.Tensor, shape, like: torch.Tensor) -> torch.Tensor:
    """``op^T y`` for a linear ``op`` taking tensors of ``shape``: the vector-Jacobian product at zero."""
    x = torch.zeros(shape, dtype=like.dtype, device=like.device, requires_grad=True)
    with torch.enable_grad():
        (g,) = torch.autograd.grad(op(x), x, y)
    return g


@PROJECTORS.register("matrix_free")
class VoxelProjector:
    """The linear map x (nx, ny, nz) -> deflections (R, 3) of R rays, and its adjoint.

    Args:
        box: the probe grid. origins, dirs: (R, 3) rays [mm], unit directions.
        step_mm: quadrature step (default half a voxel, as the voxel forward model).
        chunk: rays per batch.
    """

    def __init__(self, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor, step_mm: Optional[float] = None,
                 chunk: int = 1 << 14):
        self.box, self.origins, self.dirs = box, origins, dirs
        self.step_mm, self.chunk = step_mm, int(chunk)
        self.shape = tuple(box.shape)

    def _chunks(self):
        return range(0, len(self.dirs), self.chunk)

    def _forward(self, x: torch.Tensor, i: int) -> torch.Tensor:
        sl = slice(i, i + self.chunk)
        return voxel_deflection(x, self.box, self.origins[sl], self.dirs[sl], self.step_mm, chunk=self.chunk)

    def Ax(self, x: torch.Tensor) -> torch.Tensor:
        """(nx, ny, nz) -> (R, 3)."""
        with torch.no_grad():
            return torch.cat([self._forward(x, i) for i in self._chunks()])

    def Atb(self, y: torch.Tensor) -> torch.Tensor:
        """(R, 3) -> (nx, ny, nz)."""
        out = None
        for i in self._chunks():
            g = adjoint(lambda v: self._forward(v, i), y[i:i + self.chunk], self.shape, y)
            out = g if out is None else out + g
        return out


def interpolation_matrix(box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor, step_mm: Optional[float] = None,
                         chunk: int = 1 << 14) -> torch.Tensor:
    """S: (R, V) sparse COO, ``(S v)_r = sum_i v(p_ri) dt_ri`` for a voxel field v flattened as (nx, ny, nz),
    with the samples and the border-clamped trilinear weights of :func:`nerif.renderers.voxel.voxel_deflection`."""
    sampler = chord_sampler(box, step_mm)
    n = torch.as_tensor(box.shape, device=dirs.device)
    half = torch.as_tensor(box.half_mm, dtype=dirs.dtype, device=dirs.device)
    parts = []
    for i in range(0, len(dirs), chunk):
        s = sampler(box, origins[i:i + chunk], dirs[i:i + chunk])
        u = ((s.positions + half) / box.voxel_mm - 0.5).clamp(min=torch.zeros_like(half), max=(n - 1).to(half))
        i0 = torch.minimum(u.floor().long(), n - 2)
        f = u - i0
        rows, cols, vals = [], [], []
        for corner in range(8):
            c = torch.tensor([(corner >> 2) & 1, (corner >> 1) & 1, corner & 1], device=dirs.device)
            idx = i0 + c
            w = torch.where(c.bool(), f, 1 - f).prod(-1) * s.dt
            rows.append(s.ray_index + i)
            cols.append((idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2])
            vals.append(w)
        part = torch.sparse_coo_tensor(torch.stack([torch.cat(rows), torch.cat(cols)]), torch.cat(vals),
                                       (len(dirs), int(n.prod())), check_invariants=False).coalesce()
        parts.append(part)
    idx = torch.cat([p.indices() for p in parts], 1)
    val = torch.cat([p.values() for p in parts])
    return torch.sparse_coo_tensor(idx, val, (len(dirs), int(n.prod())), is_coalesced=True, check_invariants=False)


@PROJECTORS.register("sparse")
class SparseProjector:
    """``A = S G`` with S stored (CSR, and its transpose); same arguments as :class:`VoxelProjector`."""

    @staticmethod
    def memory_bytes(box: ProbeBox, n_rays: int, step_mm: Optional[float] = None) -> float:
        """Upper bound of the memory S and its transpose take (8 trilinear weights per sample, int64 + float)."""
        return 2 * n_rays * chord_sampler(box, step_mm).samples_per_ray * 8 * 12.0

    def __init__(self, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor, step_mm: Optional[float] = None,
                 chunk: int = 1 << 14):
        self.box, self.shape = box, tuple(box.shape)
        S = interpolation_matrix(box, origins, dirs, step_mm, chunk)
        self.nnz = S._nnz()
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Sparse CSR tensor support is in beta")
            self.S = S.to_sparse_csr()
            self.St = S.t().coalesce().to_sparse_csr()

    def _grad(self, x: torch.Tensor) -> torch.Tensor:
        return gradient_volume(x, self.box.voxel_mm).reshape(3, -1).T  # (V, 3)

    def Ax(self, x: torch.Tensor) -> torch.Tensor:
        """(nx, ny, nz) -> (R, 3)."""
        return self.S @ self._grad(x)

    def Atb(self, y: torch.Tensor) -> torch.Tensor:
        """(R, 3) -> (nx, ny, nz)."""
        return adjoint(self._grad, self.St @ y, self.shape, y)
