"""Solvers, chosen by ``solver=<name>``: each entry checks its config (cheaply, before any data is made) and
returns a builder ``make(scene, masks) -> IterativeSolver``."""
from __future__ import annotations

from omegaconf import DictConfig

from nerif.baselines.cgls import REGULARIZERS
from nerif.baselines.solver import CGLSSolver
from nerif.field import build_field
from nerif.losses import AmbientBoundary
from nerif.registry import Registry
from nerif.renderers import SAMPLERS
from nerif.trainer import Trainer

SOLVERS = Registry("solver")


@SOLVERS.register("nerif")
def neural(cfg: DictConfig):
    """The neural field (``encoder``, ``field``, ``grad``, ``sampler``, ``loss``, ``train`` groups)."""
    sampler = SAMPLERS.build(cfg.sampler)
    tc = cfg.train

    def make(scene, masks):
        field = build_field(cfg, scene.box, gate=masks.gate, data_prior=scene.sigma_prior).to(scene.dirs.device)
        boundary = AmbientBoundary(scene.box, list(cfg.loss.ambient_faces), cfg.loss.ambient_weight,
                                   cfg.loss.ambient_points)
        t = Trainer(field, scene, sampler, dict(cfg.grad.weights), iterations=tc.iterations, boundary=boundary,
                    rays_per_view=tc.rays_per_view, lr=tc.lr, betas=tuple(tc.betas), eps=tc.eps, lr_min=tc.lr_min,
                    eval_rays_per_view=tc.eval_rays_per_view, flame_threshold_K=cfg.metrics.flame_threshold_K,
                    seed=cfg.seed, inside=masks.inside, outside_fraction=tc.outside_fraction)
        t.labels.update(encoder=cfg.encoder.name, grad=cfg.grad.name)
        return t

    return make


@SOLVERS.register("cgls")
def voxel_cgls(cfg: DictConfig):
    """Voxel CGLS (``solver`` group: iterations, regularizer, lam, tol, ...) on the same scene and masks."""
    sc = cfg.solver
    REGULARIZERS.get(sc.regularizer)

    def make(scene, masks):
        s = CGLSSolver(scene, iterations=sc.iterations, regularizer=sc.regularizer, lam=sc.lam, tol=sc.tol,
                       reweight_every=sc.reweight_every, tv_eps=sc.tv_eps, ambient_faces=list(cfg.loss.ambient_faces),
                       mask_volume=masks.volume, projector=sc.projector, max_matrix_gib=sc.max_matrix_gib,
                       step_mm=sc.step_mm, chunk=sc.chunk, dtype=sc.dtype,
                       flame_threshold_K=cfg.metrics.flame_threshold_K)
        s.labels.update(regularizer=sc.regularizer, lam=float(sc.lam))
        return s

    return make
