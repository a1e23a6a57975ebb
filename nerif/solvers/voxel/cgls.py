"""CGLS for voxel BOS tomography, plain or regularised: ``min |A x - b|^2 + lam |L x|^2``.

Conjugate gradients on the normal equations of the stacked system ``[A; sqrt(lam) L] x = [b; 0]`` (Hestenes-
Stiefel CGLS, one ``Ax`` and one ``Atb`` per iteration). Regularisers ``L`` (registered in
:data:`REGULARIZERS`): ``none``; ``tikhonov`` (identity); ``laplacian`` (7-point, smoothness); ``tv`` (total
variation by iteratively reweighted norms, IRN-TV: ``L = W^(1/2) D`` with D forward differences and
``W = 1 / sqrt(|D x|^2 + tv_eps^2)`` recomputed every ``reweight_every`` iterations, CG restarted from the current
x). A 0/1 ``mask`` restricts the unknowns. The state is a few volumes; :meth:`CGLS.step` does one iteration.
"""
from __future__ import annotations

from typing import Callable, Optional

import torch

from nerif.solvers.voxel.projector import adjoint
from nerif.registry import Registry

REGULARIZERS = Registry("regularizer", package="nerif.solvers.voxel")


def forward_differences(x: torch.Tensor) -> torch.Tensor:
    """(nx, ny, nz) -> (3, nx, ny, nz); zero across the last face of each axis."""
    return torch.stack([torch.diff(x, dim=a, append=x.narrow(a, x.shape[a] - 1, 1)) for a in range(3)])


def laplacian(x: torch.Tensor) -> torch.Tensor:
    """7-point Laplacian with zero (ambient) outside the grid; a symmetric operator."""
    k = torch.zeros(3, 3, 3, dtype=x.dtype, device=x.device)
    k[1, 1, 1] = -6
    for a, b, c in ((0, 1, 1), (2, 1, 1), (1, 0, 1), (1, 2, 1), (1, 1, 0), (1, 1, 2)):
        k[a, b, c] = 1
    return torch.nn.functional.conv3d(x[None, None], k[None, None], padding=1)[0, 0]


@REGULARIZERS.register("none")
def no_regularizer():
    return None


@REGULARIZERS.register("tikhonov")
def tikhonov():
    return lambda x, w: x


@REGULARIZERS.register("laplacian")
def smoothness():
    return lambda x, w: laplacian(x)


@REGULARIZERS.register("tv")
def total_variation():
    return lambda x, w: w.sqrt() * forward_differences(x)


class CGLS:
    """Regularised CGLS state.

    Args:
        Ax, Atb: the projector pair (volume -> data, data -> volume).
        b: data, any shape ``Ax`` returns. shape: the volume shape.
        regularizer: a :data:`REGULARIZERS` name. lam: its weight.
        mask: (nx, ny, nz) 0/1 unknowns (None: all voxels).
        reweight_every, tv_eps: IRN-TV settings (weights from the current x every so many iterations).
    """

    def __init__(self, Ax: Callable, Atb: Callable, b: torch.Tensor, shape, *, regularizer: str = "none",
                 lam: float = 0.0, mask: Optional[torch.Tensor] = None, reweight_every: int = 20,
                 tv_eps: float = 1e-3, x0: Optional[torch.Tensor] = None):
        self._A, self._At, self.b, self.shape = Ax, Atb, b, tuple(shape)
        self.L = REGULARIZERS.build({"name": regularizer})
        self.tv = regularizer == "tv"
        if self.L is not None and not lam > 0:
            raise ValueError(f"regularizer '{regularizer}' needs a weight lam > 0, got {lam}")
        self.sq_lam = float(lam) ** 0.5 if self.L is not None else 0.0
        self.mask = mask
        self.reweight_every, self.tv_eps = int(reweight_every), float(tv_eps)
        self.x = torch.zeros(self.shape, dtype=b.dtype, device=b.device) if x0 is None else x0.clone()
        self.iteration = 0
        self.b_norm = float(b.norm())
        self._restart()

    # --- the stacked operator K = [A; sqrt(lam) L] P and its transpose ---
    def _P(self, v):
        return v if self.mask is None else v * self.mask

    def _K(self, x):
        x = self._P(x)
        reg = self.sq_lam * self.L(x, self.w) if self.L is not None else None
        return self._A(x), reg

    def _Kt(self, r, rr):
        g = self._At(r)
        if rr is not None:
            g = g + self.sq_lam * adjoint(lambda v: self.L(v, self.w), rr, self.shape, rr)
        return self._P(g)

    def _restart(self) -> None:
        """Residuals from the current x and a fresh search direction (also after each TV reweighting)."""
        self.w = None
        if self.tv:
            gx = forward_differences(self._P(self.x))
            self.w = 1.0 / torch.sqrt((gx**2).sum(0, keepdim=True) + self.tv_eps**2)
        ax, lx = self._K(self.x)
        self.r = self.b - ax
        self.rr = -lx if lx is not None else None
        self.s = self._Kt(self.r, self.rr)
        self.p = self.s.clone()
        self.gamma = float((self.s**2).sum())

    def step(self) -> float:
        """One iteration; returns the relative data residual |b - A x| / |b|."""
        if self.tv and self.iteration > 0 and self.iteration % self.reweight_every == 0:
            self._restart()
        if self.gamma > 0:
            q, qr = self._K(self.p)
            qq = float((q**2).sum()) + (float((qr**2).sum()) if qr is not None else 0.0)
            alpha = self.gamma / qq if qq > 0 else 0.0
            self.x += alpha * self.p
            self.r -= alpha * q
            if qr is not None:
                self.rr -= alpha * qr
            self.s = self._Kt(self.r, self.rr)
            gamma = float((self.s**2).sum())
            self.p = self.s + (gamma / self.gamma) * self.p
            self.gamma = gamma
        self.iteration += 1
        return self.residual()

    def residual(self) -> float:
        return float(self.r.norm()) / max(self.b_norm, 1e-300)

    def solution(self) -> torch.Tensor:
        return self._P(self.x)

    def state_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("x", "r", "rr", "s", "p", "gamma", "w", "iteration")}

    def load_state_dict(self, st: dict) -> None:
        for k, v in st.items():
            setattr(self, k, v)
