"""Multiresolution hash encoding (Instant-NGP, Mueller et al. 2022): per level, the trilinear (or smoothstep)
blend of the feature vectors stored at the 8 corners of the point's cell, the corners of fine levels hashed into
a table of ``2^log2_table_size`` entries. (N, 3) in [-1, 1]^3 -> (N, n_levels n_features). The fused kernels
for positions that need no gradient are in :mod:`nerif.encoders.hash_kernel`."""
import functools
import logging
import math
from typing import Optional

import torch
from torch import nn

from nerif.encoders import hash_kernel
from nerif.encoders.base import ENCODERS

log = logging.getLogger(__name__)

# Spatial-hash primes of Teschner et al. / instant-ngp.
_PRIMES = (1, 2654435761, 805459861)


class _Gather(torch.autograd.Function):
    """``table[index]`` with an ``index_add_`` backward (faster on CPU than embedding's), itself differentiable
    so that a loss on autograd gradients of the encoding can train the table (double backward)."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(index)
        ctx.n_rows = table.shape[0]
        return table.index_select(0, index)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (index,) = ctx.saved_tensors
        return _Scatter.apply(grad, index, ctx.n_rows), None


class _Scatter(torch.autograd.Function):
    @staticmethod
    def forward(ctx, values: torch.Tensor, index: torch.Tensor, n_rows: int) -> torch.Tensor:
        ctx.save_for_backward(index)
        return values.new_zeros(n_rows, values.shape[1]).index_add_(0, index, values)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (index,) = ctx.saved_tensors
        return _Gather.apply(grad, index), None, None


@ENCODERS.register("hash")
class HashGrid(nn.Module):
    """Multiresolution hash encoding (instant-ngp), all levels evaluated at once.

    Level l has ``r_l = floor(base * g^l)`` cells per axis over the unit cube (g geometric from
    ``base_resolution`` to ``max_resolution``). Its grid points index a table of its own directly while they
    fit in ``2^log2_table_size`` entries (power-of-two strides, so the index is the XOR of disjoint bit
    fields), and through the spatial hash ``x ^ y * 2654435761 ^ z * 805459861`` otherwise; both are
    ``(x m0 ^ y m1 ^ z m2) mod size_l`` with per-level multipliers, exact in int32 because the primes are
    reduced modulo the power-of-two table size. Corners are blended with trilinear weights, or with smoothstep
    weights ``w = t^2 (3 - 2 t)`` (``interpolation='smoothstep'``, the paper's: C1, so the encoding has second
    derivatives, but flat at every grid node, so that a level alone renders a ramp as a staircase of its cell
    size, which the finer levels must cancel; with few views the data do not pin that cancellation down and the
    field keeps axis-aligned blocks: twice the error of trilinear weights on flame families, issue 12).

    ``kernel``: the fused kernels of :mod:`nerif.encoders.hash_kernel` evaluate the encoding wherever positions need
    no gradient (central differences, evaluation, the occupancy grid; ``grad=auto`` differentiates the encoding by
    position and takes the tensor path): ``auto`` takes ``triton`` on CUDA and ``cpp`` on the CPU once they have been
    checked against the tensor path on this device (:func:`kernels_agree`; else the tensor path, with one warning);
    ``torch`` always takes the tensor path (the reference); ``triton`` or ``cpp`` name a backend outright (the
    tests run ``triton`` on the CPU in Triton's interpreter).

    (N, 3) in [-1, 1]^3 -> (N, n_levels * n_features). Defaults: the CPU default scene's (8 levels 16 -> 64,
    2^15 entries, trilinear); the paper's are 16 levels 16 -> 512 and 2^19 entries (``+experiment=paper_phantom5``).
    """

    @staticmethod
    def features(encoder) -> int:
        """Features a point (``encoder``: this group's config)."""
        return int(encoder["n_levels"]) * int(encoder["n_features"])

    @staticmethod
    def allocations(cfg) -> list[tuple[str, str, float]]:
        """The tables, with their gradients, Adam's moments and the average (:mod:`nerif.memory`)."""
        e = cfg["encoder"]
        entries = float(e["n_levels"]) * 2.0 ** float(e["log2_table_size"]) * float(e["n_features"])
        return [("the hash tables", "field.log2_table_size", entries * 5 * 4)]

    def __init__(
        self,
        n_levels: int = 8,
        n_features: int = 2,
        log2_table_size: int = 15,
        base_resolution: int = 16,
        max_resolution: int = 64,
        init_scale: float = 1e-4,
        interpolation: str = "linear",
        kernel: str = "auto",
    ):
        super().__init__()
        if interpolation not in ("smoothstep", "linear"):
            raise ValueError(f"hash interpolation must be 'smoothstep' or 'linear', got '{interpolation}'")
        if kernel not in ("auto", "torch") + hash_kernel.BACKENDS:
            raise ValueError(f"hash kernel must be auto, torch, {' or '.join(hash_kernel.BACKENDS)}, got '{kernel}'")
        if kernel in hash_kernel.BACKENDS and not hash_kernel.available(kernel):
            raise ValueError(f"hash kernel '{kernel}' cannot run here ({_NEEDS[kernel]}): use encoder.kernel=auto")
        self.kernel = kernel
        for what, n in (("field.hash_levels", n_levels), ("encoder.n_features", n_features)):
            if isinstance(n, bool) or not isinstance(n, int) or n < 1:  # 0 levels: the CPU kernel divides by it
                raise ValueError(f"{what}={n!r} must be a whole number of at least 1")
        if not 1 <= base_resolution <= max_resolution:
            raise ValueError(f"hash resolutions need 1 <= base ({base_resolution}) <= max ({max_resolution})")
        if not 4 <= log2_table_size <= 24:
            raise ValueError(f"log2_table_size must be within 4..24, got {log2_table_size}")
        self.interpolation = interpolation
        self.n_levels, self.n_features = n_levels, n_features
        self.out_dim = n_levels * n_features
        self.cells_across = max_resolution  # the finest level's cells across the network's [-1, 1]
        growth = math.exp((math.log(max_resolution) - math.log(base_resolution)) / max(n_levels - 1, 1))
        res = [int(math.floor(base_resolution * growth**l + 1e-6)) for l in range(n_levels)]
        table = 2**log2_table_size
        sizes, mults = [], []
        for r in res:
            stride = 1 << math.ceil(math.log2(r + 1))
            if stride**3 <= table:  # dense: x + y S + z S^2 = x ^ (y S) ^ (z S^2)
                sizes.append(stride**3)
                mults.append((1, stride, stride * stride))
            else:
                sizes.append(table)
                mults.append(tuple(p % table for p in _PRIMES))
        self.resolutions = res
        self.register_buffer("resolution", torch.tensor(res, dtype=torch.float32), persistent=False)
        self.register_buffer("mask", torch.tensor(sizes, dtype=torch.int32) - 1, persistent=False)
        self.register_buffer("offset", torch.tensor([0] + sizes[:-1]).cumsum(0).int(), persistent=False)
        self.register_buffer("mult", torch.tensor(mults, dtype=torch.int32), persistent=False)  # (L, 3)
        self.table = nn.Parameter(torch.empty(sum(sizes), n_features).uniform_(-init_scale, init_scale))

    def backend(self, x: torch.Tensor) -> Optional[str]:
        """The fused backend that encodes ``x``, or None for the tensor path (see the class docstring)."""
        if self.kernel == "torch" or x.requires_grad or self.table.dtype != torch.float32:  # kernels: float32 only
            return None
        if self.kernel in hash_kernel.BACKENDS:
            return self.kernel
        backend = {"cuda": "triton", "cpu": "cpp"}.get(x.device.type)
        return backend if backend is not None and kernels_agree(backend, x.device) else None

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        backend = self.backend(x)
        if backend is not None:
            return hash_kernel.FusedHashEncoding.apply(x, self.table, self.resolution, self.mask, self.offset,
                                                       self.mult, self.interpolation == "smoothstep", backend)
        n, L = x.shape[0], self.n_levels
        u = ((x + 1) * 0.5).clamp(0.0, 1.0)
        pos = u[:, None, :] * self.resolution[None, :, None]  # (N, L, 3)
        cell = torch.minimum(pos.detach().floor(), (self.resolution - 1)[None, :, None])
        t = pos - cell  # differentiable in x
        if self.interpolation == "smoothstep":
            t = t * t * (3.0 - 2.0 * t)
        c = cell.int()
        # per axis and corner bit: index term (N, L, 3, 2) and weight (N, L, 3, 2)
        term = torch.stack([c, c + 1], -1) * self.mult[None, :, :, None]
        w = torch.stack([1 - t, t], -1)
        index = term[:, :, 0, :, None, None] ^ term[:, :, 1, None, :, None] ^ term[:, :, 2, None, None, :]
        index = (index.reshape(n, L, 8) & self.mask[None, :, None]) + self.offset[None, :, None]
        weight = (w[:, :, 0, :, None, None] * w[:, :, 1, None, :, None] * w[:, :, 2, None, None, :]).reshape(n * L, 1, 8)
        feats = _Gather.apply(self.table, index.reshape(-1).long()).reshape(n * L, 8, self.n_features)
        if x.is_cuda:  # a batched 1 x 8 by 8 x F product is slow in cuBLAS (3/4 of a GPU step); on the CPU it wins
            return (weight.transpose(1, 2) * feats).sum(1).reshape(n, L * self.n_features)
        return torch.bmm(weight, feats).reshape(n, L * self.n_features)


_NEEDS = {"triton": "Triton is not installed; it ships with CUDA builds of PyTorch",
          "cpp": "no C++ compiler or ninja on the PATH"}


@functools.lru_cache(maxsize=None)
def kernels_agree(backend: str, device: torch.device) -> bool:
    """Whether the ``backend`` kernels run on ``device`` and give the tensor path's values and table gradients on a
    small random encoding (checked once per backend and device). If not, ``kernel=auto`` keeps the tensor path and
    one warning says why: a missing compiler, or a Triton or driver that cannot build them, costs speed, not the
    run."""
    if not hash_kernel.available(backend):
        ok, why = False, _NEEDS[backend]
    else:
        try:
            with torch.enable_grad():  # the first call may come from an evaluation under no_grad
                ok = _kernels_match(backend, device)
            why = "they differ from the tensor path"
        except Exception as e:  # a compiler or driver error: report it, keep the tensor path
            ok, why = False, f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"
    if not ok:
        log.warning("the fused hash kernels (%s) do not work on %s (%s): the hash encoding takes the tensor path "
                    "(encoder.kernel=torch; slower)", backend, device, why)
    return ok


def _kernels_match(backend: str, device: torch.device) -> bool:
    """The ``backend`` kernels against the tensor path on 1,000 random points of a small encoding: values and
    table gradients within float32 tolerance."""
    g = torch.Generator().manual_seed(0)
    ref = HashGrid(n_levels=3, log2_table_size=10, base_resolution=4, max_resolution=32, init_scale=1.0,
                   kernel="torch").to(device)
    x = (torch.rand(1000, 3, generator=g) * 2.2 - 1.1).to(device)
    w = torch.randn(1000, ref.out_dim, generator=g).to(device)
    y_ref = ref(x)
    y = hash_kernel.FusedHashEncoding.apply(x, ref.table, ref.resolution, ref.mask, ref.offset, ref.mult, False,
                                            backend)
    (g_ref,) = torch.autograd.grad(y_ref, ref.table, w)
    (g_fused,) = torch.autograd.grad(y, ref.table, w)
    return torch.allclose(y, y_ref, rtol=1e-4, atol=1e-5) and torch.allclose(g_fused, g_ref, rtol=1e-4, atol=1e-5)
