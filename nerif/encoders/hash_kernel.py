"""Fused multiresolution hash encodings: one pass per point and level instead of a chain of tensor ops.

:class:`nerif.encoders.hash.HashGrid` evaluates every level with tensor operations: per sample and level it builds
the 8 corner indices and weights as tensors, gathers the table rows and blends them, and autograd keeps each of
those tensors for the backward pass. On a GPU the blend alone (a batched 1 x 8 by 8 x F product) took three
quarters of a training step at the paper's scale; on the CPU the encoding is most of a step (benchmarks/RESULTS.md).
Here the corners, their weights, the gathers and the blend are computed per point in registers and only the
(N, L F) encoding is written; the backward pass recomputes the corners and adds ``w * dL/dy`` into the table's
gradient. Two backends compute the same function as the tensor path (same cells, hashing and weights):

- ``triton`` (CUDA): one program per block of :data:`BLOCK` points and one level; atomic adds in the backward pass.
  Triton ships with CUDA builds of PyTorch; on the CPU its interpreter runs it (``TRITON_INTERPRET=1``, the tests).
- ``cpp`` (CPU): ``hash_cpu.cpp``, compiled once per Python environment by ``torch.utils.cpp_extension`` (a C++
  compiler with OpenMP, and ninja, which nerif depends on): points in parallel forward, levels in parallel backward
  (each level owns its rows of the table: no atomics).

Positions get no gradient, so the encoder takes these paths only when they need none (the ``discrete`` central
differences, evaluation, the occupancy grid), and the tensor path otherwise.
"""
from __future__ import annotations

import functools
import hashlib
import logging
import os
import shutil
import sys
from pathlib import Path

import torch

try:
    import triton
    import triton.language as tl
except ImportError:  # no Triton (a CPU build of PyTorch): the cpp backend only
    triton = None
try:  # the ninja package's binary, where the environment's bin/ is not on the PATH (a venv's python run directly)
    import ninja

    if ninja.BIN_DIR not in os.environ.get("PATH", "").split(os.pathsep):
        os.environ["PATH"] = os.pathsep.join([ninja.BIN_DIR, os.environ.get("PATH", "")])
except (ImportError, AttributeError):
    pass

log = logging.getLogger(__name__)

BACKENDS = ("triton", "cpp")


def available(backend: str) -> bool:
    """Whether ``backend`` can run here at all: Triton importable, or a C++ compiler on the PATH (whether it builds
    is known only once it has: :func:`cpp_module`)."""
    if backend == "triton":
        return triton is not None
    from torch.utils.cpp_extension import verify_ninja_availability

    try:
        verify_ninja_availability()
    except RuntimeError:
        return False
    return shutil.which("c++") is not None or shutil.which("g++") is not None


def build_directory() -> Path:
    """Where this Python environment keeps its build of the CPU kernel: torch's extension cache
    (``$TORCH_EXTENSIONS_DIR``, default ``~/.cache/torch_extensions``), in a folder of its own per environment and
    torch version, so that two environments on one machine do not rebuild each other's."""
    key = hashlib.sha1(f"{sys.prefix}|{torch.__version__}".encode()).hexdigest()[:12]
    root = os.environ.get("TORCH_EXTENSIONS_DIR") or Path.home() / ".cache" / "torch_extensions"
    folder = Path(root) / f"nerif_hash_cpu_{key}"
    folder.mkdir(parents=True, exist_ok=True)
    return folder


@functools.lru_cache(maxsize=1)
def cpp_module():
    """The compiled CPU kernels (built on first use, then loaded from this environment's :func:`build_directory`,
    rebuilt when the source or the flags change)."""
    from torch.utils.cpp_extension import load_inline

    source = (Path(__file__).with_name("hash_cpu.cpp")).read_text()
    log.info("loading the CPU hash-encoding kernel (compiled on first use, about 20 s; cached after)")
    return load_inline("nerif_hash_cpu", cpp_sources=[source], functions=["hash_forward", "hash_backward"],
                       extra_cflags=["-O3", "-fopenmp"], extra_ldflags=["-fopenmp"], verbose=False,
                       build_directory=str(build_directory()))


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


# points per program: 128 on a GPU; 512 in Triton's interpreter, where a program is a sequence of NumPy steps in
# Python (fewer, larger ones: half the interpreted kernels' time, the same function)
BLOCK = 512 if os.environ.get("TRITON_INTERPRET") == "1" else 128


class FusedHashEncoding(torch.autograd.Function):
    """(N, 3) positions in [-1, 1]^3 (no gradient) and the table (T, F) -> (N, L F) by ``backend``; see the module
    docstring."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, table: torch.Tensor, resolution: torch.Tensor, mask: torch.Tensor,
                offset: torch.Tensor, mult: torch.Tensor, smooth: bool, backend: str) -> torch.Tensor:
        n, L, F = x.shape[0], resolution.shape[0], table.shape[1]
        x = x.detach().contiguous().float()
        table, mult = table.detach().contiguous(), mult.contiguous()
        if backend == "cpp":
            y = cpp_module().hash_forward(x, table, resolution, mask, offset, mult, smooth)
        else:
            y = torch.empty(n, L * F, device=x.device, dtype=torch.float32)
            if n:
                _forward[(triton.cdiv(n, BLOCK), L)](x, table, y, resolution, mask, offset, mult, n, L, F=F,
                                                     BLOCK=BLOCK, SMOOTH=smooth)
        ctx.save_for_backward(x, resolution, mask, offset, mult)
        ctx.table_shape, ctx.smooth, ctx.backend = table.shape, smooth, backend
        return y

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, grad_y: torch.Tensor):
        x, resolution, mask, offset, mult = ctx.saved_tensors
        n, L, F = x.shape[0], resolution.shape[0], ctx.table_shape[1]
        grad_y = grad_y.contiguous().float()
        if ctx.backend == "cpp":
            grad_table = cpp_module().hash_backward(x, grad_y, ctx.table_shape[0], resolution, mask, offset, mult,
                                                    ctx.smooth)
        else:
            grad_table = torch.zeros(ctx.table_shape, device=x.device, dtype=torch.float32)
            if n:
                _backward[(triton.cdiv(n, BLOCK), L)](x, grad_y, grad_table, resolution, mask, offset, mult, n, L,
                                                      F=F, BLOCK=BLOCK, SMOOTH=ctx.smooth)
        return None, grad_table, None, None, None, None, None, None
