"""Voxel CGLS as a solver interchangeable with the neural one: same scene, masks, metrics, loop and outputs."""
from __future__ import annotations

import hashlib
import inspect
import time
from typing import Mapping, Optional

import numpy as np
import torch

from nerif.geometry import box_faces
from nerif.renderers.deflection import perpendicular
from nerif.renderers.voxel import voxel_deflection
from nerif.sensing.interpolation import interpolation
from nerif.solvers.base import SOLVERS, IterativeSolver, check_faces
from nerif.solvers.data_terms import DATA_TERMS, noise_weights
from nerif.solvers.voxel.cgls import CGLS, REGULARIZERS
from nerif.solvers.voxel.projector import PROJECTORS, SparseProjector
from nerif.solvers.voxel.unified import unified_system
from nerif.units import declare
declare(rays="rays", unknowns="voxels", relative_residual="1 (|r| / |b|)", lam="1 (weight)",
        text=("projector", "regularizer"))


def boundary_mask(shape, faces) -> np.ndarray:
    """(nx, ny, nz) bool, False on the voxels of the given faces of the grid (names as
    :func:`nerif.geometry.box_faces`: ``x`` both faces of that axis, ``-x`` one)."""
    keep = np.ones(shape, bool)
    for axis, side in box_faces(faces):
        idx = [slice(None)] * 3
        idx[axis] = 0 if side < 0 else -1
        keep[tuple(idx)] = False
    return keep


_LAST_PROJECTOR: dict = {}


def built_projector(name: str, box, origins: torch.Tensor, dirs: torch.Tensor, step_mm, chunk: int):
    """The projector for these rays, reusing the last one built in this process when the rays and grid are the
    same (sweeps and benchmarks run many solvers on one scene; a sparse matrix takes seconds to build)."""
    digest = hashlib.sha256(origins.cpu().numpy().tobytes() + dirs.cpu().numpy().tobytes()).hexdigest()
    key = (name, box, step_mm, chunk, str(dirs.dtype), str(dirs.device), digest)
    if _LAST_PROJECTOR.get("key") != key:
        _LAST_PROJECTOR.clear()  # one at a time: bounded memory
        _LAST_PROJECTOR.update(key=key, projector=PROJECTORS.build(
            {"name": name}, box=box, origins=origins, dirs=dirs, step_mm=step_mm, chunk=chunk))
    return _LAST_PROJECTOR["projector"]


# the data_term settings CGLS reads (two-step and unified BOS); any other one set away from its default is refused
VOXEL_READS = ("name", "highpass_px", "lowpass_px", "noise_weighted")
# how unified BOS reads the reference: the bandlimited reading of the image term was better on 10 of the 13 shared
# captures (geometric mean 0.89x) but worse on 3 (1.006-1.015x) with TV 0.1 (benchmarks/RESULTS.md, issue 68): kept
UNIFIED_READ = interpolation("bicubic")


def settings_not_read(data_term: Mapping) -> list[str]:
    """``data_term.KEY=VALUE`` of each setting of ``data_term`` that CGLS does not read (not in :data:`VOXEL_READS`)
    and that differs from its data term's default (the registered class's): a new setting of a data term is
    refused here until CGLS reads it."""
    defaults = inspect.signature(DATA_TERMS.get(data_term["name"]).__init__).parameters
    return [f"data_term.{k}={v}" for k, v in data_term.items()
            if k not in VOXEL_READS and (k not in defaults or v != defaults[k].default)]


@SOLVERS.register("cgls")
class CGLSSolver(IterativeSolver):
    """CGLS on every ray of the scene for sigma on the probe grid (``solver=cgls``).

    The deflections fix sigma up to a constant; as the neural solver's ambient boundary condition does, the
    voxels of ``ambient_faces`` are held at sigma = 0 (ambient gas), which removes that null space. A 3-D mask
    restricts the unknowns further.

    Args:
        iterations: CGLS iterations (upper bound). eval_every, metrics, seed, label: see :class:`IterativeSolver`.
        regularizer, lam, reweight_every, tv_eps: see :class:`nerif.solvers.voxel.cgls.CGLS`.
        tol: stop once |b - A x| / |b| falls below it (discrepancy principle; None: run all iterations).
        ambient_faces, crossed_cover, ambient_fallback: the faces held at sigma = 0 (``loss.ambient_faces``:
            ``auto`` or a list; see
            :meth:`IterativeSolver.resolve_ambient_faces`).
        projector: ``sparse``, ``matrix_free`` or ``auto`` (sparse when its matrix fits in ``max_matrix_gib``).
        step_mm, chunk: projector quadrature step and rays per batch. dtype: ``float32`` or ``float64``.
    """

    name = "cgls"

    def __init__(self, *, iterations: int, eval_every: int, regularizer: str, lam: float, tol: Optional[float],
                 reweight_every: int, tv_eps: float, ambient_faces, crossed_cover: float, ambient_fallback,
                 projector: str, max_matrix_gib: float,
                 step_mm: Optional[float], chunk: int, dtype: str, metrics: Mapping, seed: int, label: str,
                 data_term: Optional[Mapping] = None, linearize_at: str = "flow", poses: Optional[Mapping] = None):
        super().__init__(iterations=iterations, eval_every=eval_every, metrics=metrics, seed=seed, label=label)
        if poses is not None and poses["name"] != "given":
            raise ValueError(f"poses={poses['name']}: the voxel solver keeps the rig's poses as given; refine them "
                             "with solver=nerif")
        if not lam >= 0:
            raise ValueError(f"solver.lam={lam}: a regularisation weight is at least 0")
        if REGULARIZERS.build({"name": regularizer}) is not None and not lam > 0:
            raise ValueError(f"regularizer '{regularizer}' needs a weight solver.lam > 0, got {lam}")
        if projector != "auto":
            PROJECTORS.get(projector)
        if dtype not in ("float32", "float64"):
            raise ValueError(f"solver.dtype must be float32 or float64, got '{dtype}'")
        check_faces(ambient_faces)
        check_faces(ambient_fallback, "loss.ambient_fallback", auto=False)
        self.regularizer, self.lam, self.tol = regularizer, float(lam), tol
        self.reweight_every, self.tv_eps = int(reweight_every), float(tv_eps)
        self.ambient_setting, self.ambient_fallback = ambient_faces, ambient_fallback
        self.crossed_cover = float(crossed_cover)
        self.projector_name, self.max_matrix_gib = projector, float(max_matrix_gib)
        self.step_mm, self.chunk, self.dtype = step_mm, int(chunk), getattr(torch, dtype)
        self.data_term = dict(data_term or {"name": "flow"})
        if self.data_term["name"] not in ("flow", "images", "auto"):
            raise ValueError(f"solver=cgls fits data_term=flow (or auto: the same), or images (unified BOS), got "
                             f"'{self.data_term['name']}'")
        unused = settings_not_read(self.data_term)
        if unused:
            raise ValueError(f"{', '.join(unused)}: solver=cgls does not use {'it' if len(unused) == 1 else 'them'} "
                             "(the neural solver's image term does; unified BOS, data_term=images, takes "
                             "data_term.highpass_px and lowpass_px; both weigh the views by data_term.noise_weighted)")
        if linearize_at not in ("zero", "flow"):
            raise ValueError(f"solver.linearize_at must be zero or flow, got '{linearize_at}'")
        self.linearize_at = linearize_at
        self.labels.update(regularizer=regularizer, lam=float(lam))

    def setup(self, scene, masks) -> "CGLSSolver":
        """Build the projector for every ray of ``scene`` and the CGLS state; unknowns: the voxels off the ambient
        faces, inside ``masks.volume`` where there is one."""
        super().setup(scene, masks)
        dt = self.dtype
        origins = scene.origins[scene.ray_views()].to(dt)
        projector = self.projector_name
        if projector == "auto":
            need = SparseProjector.memory_bytes(scene.box, origins, scene.dirs.to(dt), self.step_mm)
            fits = need <= self.max_matrix_gib * 2**30
            projector = "sparse" if fits else "matrix_free"
        self.projector = built_projector(projector, scene.box, origins, scene.dirs.to(dt), self.step_mm, self.chunk)
        self.projector_name = projector
        faces = self.resolve_ambient_faces(self.ambient_setting, masks, self.crossed_cover, self.ambient_fallback)
        unknown = boundary_mask(scene.box.shape, faces)
        if masks.volume is not None:
            unknown &= np.asarray(masks.volume) > 0.5
        if not unknown.any():
            raise ValueError("CGLS has no unknowns: the 3-D mask is empty inside the ambient faces")
        self.unknowns = int(unknown.sum())
        mask = torch.as_tensor(unknown, dtype=dt, device=self.device)
        d = scene.dirs.to(dt)
        # auto: two-step, which measured better than unified on the independent capture (benchmarks/RESULTS.md)
        self.fitted = "images" if self.data_term["name"] == "images" else "flow"
        # each ray's rows times sqrt(w_v): the views weighed by their images' noise (maximum likelihood)
        w = noise_weights(scene) if self.data_term.get("noise_weighted", True) else None
        self.row_weight = None if w is None else w.to(self.device, dt)[scene.ray_views()].sqrt()[:, None]  # (N, 1)
        rw = 1.0 if self.row_weight is None else self.row_weight
        if self.fitted == "images":  # unified BOS: rows of the images' linearised equations
            self.labels["data_term"] = "images"
            M, c = unified_system(scene, self.data_term.get("highpass_px"), self.linearize_at,
                                  lowpass_px=self.data_term.get("lowpass_px"),
                                  read=UNIFIED_READ)
            M, b = M.to(dt) * (rw if w is None else rw[..., None]), c.to(dt) * rw
            P = (lambda e: (M @ e[..., None])[..., 0])
            Pt = (lambda y: (M.transpose(1, 2) @ y[..., None])[..., 0])
        else:
            b = scene.observed.to(dt) * rw
            project = (lambda e: perpendicular(e, d)) if scene.perpendicular_only else (lambda e: e)
            P = (lambda e: project(e) * rw)
            Pt = P  # symmetric: (W P A)^T = A^T P W, W diagonal

        def Ax(x):
            return P(self.projector.Ax(x))

        def Atb(y):
            return self.projector.Atb(Pt(y))

        self.cgls = CGLS(Ax, Atb, b, scene.box.shape, regularizer=self.regularizer, lam=self.lam,
                         mask=mask, reweight_every=self.reweight_every, tv_eps=self.tv_eps)
        return self

    def step(self) -> dict:
        t0 = time.perf_counter()
        res = self.cgls.step()
        if self.device.type == "cuda":
            torch.cuda.synchronize()
        self._timed(time.perf_counter() - t0)
        return {"loss": res**2, "relative_residual": res, "converged": self.tol is not None and res < self.tol}

    def reconstruction(self) -> np.ndarray:
        return self.cgls.solution().cpu().numpy().astype(np.float64)

    def predict(self, origins: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        d = dirs.to(self.dtype)
        eps = voxel_deflection(self.cgls.solution(), self.scene.box, origins.to(self.dtype), d, self.step_mm)
        return perpendicular(eps, d) if self.scene.perpendicular_only else eps

    def evaluate(self) -> dict:
        ev = self.evaluation
        m = {"iteration": self.iteration, "wall_time_s": self.train_seconds, **ev.field_errors(self.reconstruction())}
        if self.fitted == "images":  # the residual is photometric: deflections on the evaluation rays
            m["deflection_rmse"] = ev.deflection_errors({"cgls": self.predict(*ev.train_rays())})["deflection_rmse_cgls"]
        else:
            r = self.cgls.r * self.scene.scale  # data residual [rad], weighed as the rows are
            if self.row_weight is not None:
                r = r / self.row_weight
            m["deflection_rmse"] = float((r.double() ** 2).sum(-1).mean().sqrt())
        m.update(relative_residual=self.cgls.residual(), **ev.heldout_errors(self.predict))
        self.history.append(m)
        return m

    def state_dict(self) -> dict:
        return {**super().state_dict(), "cgls": self.cgls.state_dict()}

    def load_state_dict(self, st: dict) -> None:
        super().load_state_dict(st)
        self.cgls.load_state_dict(st["cgls"])

    def timing(self) -> dict:
        return {**super().timing(), "unknowns": self.unknowns, "rays": len(self.scene.dirs),
                "projector": self.projector_name}
