"""A fused multiresolution hash encoding for CUDA (Triton): one kernel per pass instead of a chain of tensor ops.

:class:`nerif.encoders.hash.HashGrid` evaluates every level with tensor operations: per sample and level it builds
the 8 corner indices and weights as tensors, gathers the table rows and blends them, and autograd keeps each of
those tensors for the backward pass. On a GPU the blend alone (a batched 1 x 8 by 8 x F product) took three
quarters of a training step at the paper's scale (benchmarks/RESULTS.md). Here one program computes, for a block
of points and one level, the corners, their weights, the gathers and the blend in registers and writes only the
(N, L F) encoding; the backward pass recomputes the corners and adds ``w * dL/dy`` into the table's gradient with
atomic adds. It computes the same function as the reference (same cells, same hashing, same weights) and gives
the gradient with respect to the table; positions get no gradient, so the encoder takes this path only when they
need none (the ``discrete`` central differences, evaluation), and the reference otherwise.

Without Triton (a CPU-only install) the module still imports and :func:`available` says False.
"""
from __future__ import annotations

import torch


try:
    import triton
    import triton.language as tl
except ImportError:  # a CPU-only install: the reference path only
    triton = None


def available() -> bool:
    """Whether the fused kernels can run (Triton, which ships with CUDA builds of PyTorch, is importable)."""
    return triton is not None


if triton is not None:
    @triton.jit
    def _axis(x_ptr, i, live, a: tl.constexpr, r, SMOOTH: tl.constexpr):
        """Along axis ``a``: the lower cell corner (int32) and the fractional position t (smoothstep-weighted)."""
        u = tl.minimum(tl.maximum((tl.load(x_ptr + i * 3 + a, mask=live, other=0.0) + 1.0) * 0.5, 0.0), 1.0)
        pos = u * r
        c = tl.minimum(tl.floor(pos), r - 1.0)
        t = pos - c
        if SMOOTH:
            t = t * t * (3.0 - 2.0 * t)
        return c.to(tl.int32), t

    @triton.jit
    def _corners(x_ptr, res_ptr, n, level, BLOCK: tl.constexpr, SMOOTH: tl.constexpr):
        """The block's points, which of them exist, and per axis the lower cell corner and fractional position."""
        i = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
        live = i < n
        r = tl.load(res_ptr + level)
        cx, tx = _axis(x_ptr, i, live, 0, r, SMOOTH)
        cy, ty = _axis(x_ptr, i, live, 1, r, SMOOTH)
        cz, tz = _axis(x_ptr, i, live, 2, r, SMOOTH)
        return i, live, cx, tx, cy, ty, cz, tz

    @triton.jit
    def _level(x_ptr, res_ptr, mask_ptr, offset_ptr, mult_ptr, n, BLOCK: tl.constexpr, SMOOTH: tl.constexpr):
        """This program's level and points, which of them exist, and the cell of each point on that level: lower
        corner and fractional position per axis, the level's hash multipliers, table mask and offset."""
        level = tl.program_id(1)
        i, live, cx, tx, cy, ty, cz, tz = _corners(x_ptr, res_ptr, n, level, BLOCK, SMOOTH)
        m0 = tl.load(mult_ptr + level * 3)
        m1 = tl.load(mult_ptr + level * 3 + 1)
        m2 = tl.load(mult_ptr + level * 3 + 2)
        return level, i, live, (cx, tx, cy, ty, cz, tz, m0, m1, m2, tl.load(mask_ptr + level), tl.load(offset_ptr + level))

    @triton.jit
    def _corner(k: tl.constexpr, cell):
        """Corner ``k`` (bit 0: x, 1: y, 2: z) of each point's cell: its table row (int64) and trilinear weight."""
        cx, tx, cy, ty, cz, tz, m0, m1, m2, size_mask, offset = cell
        bx, by, bz = k & 1, (k >> 1) & 1, (k >> 2) & 1
        idx = (((cx + bx) * m0) ^ ((cy + by) * m1) ^ ((cz + bz) * m2)) & size_mask
        w = (tx if bx else 1.0 - tx) * (ty if by else 1.0 - ty) * (tz if bz else 1.0 - tz)
        return (idx + offset).to(tl.int64), w

    @triton.jit
    def _forward(x_ptr, table_ptr, y_ptr, res_ptr, mask_ptr, offset_ptr, mult_ptr, n, L,
                 F: tl.constexpr, BLOCK: tl.constexpr, SMOOTH: tl.constexpr):
        level, i, live, cell = _level(x_ptr, res_ptr, mask_ptr, offset_ptr, mult_ptr, n, BLOCK, SMOOTH)
        for f in tl.static_range(F):
            acc = tl.zeros([BLOCK], dtype=tl.float32)
            for k in tl.static_range(8):
                row, w = _corner(k, cell)
                acc += w * tl.load(table_ptr + row * F + f, mask=live, other=0.0)
            tl.store(y_ptr + i.to(tl.int64) * (L * F) + level * F + f, acc, mask=live)

    @triton.jit
    def _backward(x_ptr, grad_y_ptr, grad_table_ptr, res_ptr, mask_ptr, offset_ptr, mult_ptr, n, L,
                  F: tl.constexpr, BLOCK: tl.constexpr, SMOOTH: tl.constexpr):
        level, i, live, cell = _level(x_ptr, res_ptr, mask_ptr, offset_ptr, mult_ptr, n, BLOCK, SMOOTH)
        for f in tl.static_range(F):
            g = tl.load(grad_y_ptr + i.to(tl.int64) * (L * F) + level * F + f, mask=live, other=0.0)
            for k in tl.static_range(8):
                row, w = _corner(k, cell)
                tl.atomic_add(grad_table_ptr + row * F + f, w * g, mask=live, sem="relaxed")


_BLOCK = 128


class FusedHashEncoding(torch.autograd.Function):
    """(N, 3) positions in [-1, 1]^3 (no gradient) and the table (T, F) -> (N, L F); see the module docstring."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, table: torch.Tensor, resolution: torch.Tensor, mask: torch.Tensor,
                offset: torch.Tensor, mult: torch.Tensor, smooth: bool) -> torch.Tensor:
        n, L, F = x.shape[0], resolution.shape[0], table.shape[1]
        x = x.detach().contiguous().float()
        y = torch.empty(n, L * F, device=x.device, dtype=torch.float32)
        if n:
            _forward[(triton.cdiv(n, _BLOCK), L)](x, table.detach().contiguous(), y, resolution, mask, offset,
                                             mult.contiguous(), n, L, F=F, BLOCK=_BLOCK, SMOOTH=smooth)
        ctx.save_for_backward(x, resolution, mask, offset, mult)
        ctx.table_shape, ctx.smooth = table.shape, smooth
        return y

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_y: torch.Tensor):
        x, resolution, mask, offset, mult = ctx.saved_tensors
        n, L, F = x.shape[0], resolution.shape[0], ctx.table_shape[1]
        grad_table = torch.zeros(ctx.table_shape, device=x.device, dtype=torch.float32)
        if n:
            _backward[(triton.cdiv(n, _BLOCK), L)](x, grad_y.contiguous().float(), grad_table, resolution, mask, offset,
                                             mult.contiguous(), n, L, F=F, BLOCK=_BLOCK, SMOOTH=ctx.smooth)
        return None, grad_table, None, None, None, None, None
