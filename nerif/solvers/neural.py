"""The neural solver (``solver=nerif``): a neural field trained on a scene's deflections, its optimisation state
and its steps."""
from __future__ import annotations

import copy
import logging
import math
import time
from pathlib import Path
from typing import Mapping, Optional

import numpy as np
import torch

from nerif.data import Scene
from nerif.encoders import ENCODERS
from nerif.data.phantoms import read_volume
from nerif.field import (NeuralField, averaged_field, check_truth_within, fit_to_volume, prior_interval,
                         prior_saturation, prior_source)
from nerif.losses import AmbientBoundary, TotalVariation, weighted_sum
from nerif.renderers import SAMPLERS, DeflectionRenderer
from nerif.solvers.base import SOLVERS, DivergenceError, IterativeSolver, check_faces
from nerif.solvers.batches import RayBatcher, check_views_per_batch
from nerif.solvers.data_terms import DATA_TERMS
from nerif.solvers.stages import Stage, StagePlan, whose, choose

log = logging.getLogger(__name__)


@SOLVERS.register("nerif")
class NeuralSolver(IterativeSolver):
    """Adam (with AdamW's decoupled decay on the encoder's tables) + cosine annealing on batches of random rays
    drawn evenly from every view (or, as in the paper, from one view per iteration, views cycled).

    Built from ``conf/solver/nerif.yaml``, whose groups it reads:

    Args:
        encoder: an :data:`ENCODERS` config. field: ``hidden`` widths and ``prior`` interval of the MLP
            (null: the data's own, else :data:`nerif.field.DEFAULT_PRIOR`).
        grad: ``weights``, gradient operator -> loss weight (lambda_a for ``auto``, lambda_d for ``discrete``);
            ``stencil`` of the central differences (see :func:`nerif.renderers.render_deflections`).
        sampler: a :data:`SAMPLERS` config. loss: the ambient boundary condition (``ambient_faces``: ``auto`` or
            a list, ``crossed_cover``, ``ambient_fallback``, ``ambient_weight``, ``ambient_points``; see
            :class:`nerif.losses.AmbientBoundary` and :meth:`IterativeSolver.resolve_ambient_faces`).
        train: ``iterations``, ``eval_every``, ``stop_when_converged`` (stop once the best deflection RMSE on
            the fixed evaluation rays over the last ``stop_patience`` evaluations improves on the best before them
            by less than this fraction; null: never),
            ``rays_per_batch``, ``views_per_batch`` (a number, or ``all``),
            ``outside_fraction`` (share of each view's rays drawn outside its 2-D mask), Adam's ``lr``,
            ``betas``, ``eps`` with the cosine floor ``lr_min``, and ``table_decay``: each step multiplies the
            encoder's parameters by ``1 - lr table_decay`` (AdamW), so that table entries no ray constrains fade
            to zero instead of wandering under Adam's normalised steps. ``init_volume``: a ``reconstruction.npz``
            on this probe grid that the field is first fit to (``init_iterations``; :func:`nerif.field.fit_to_volume`).
            ``ema_decay``: evaluations and outputs use an exponential moving average of the trained weights
            (:func:`nerif.field.averaged_field`; 0: the last weights), training itself is unchanged.
        metrics, seed, label: see :class:`IterativeSolver`.
    """

    name = "nerif"
    starts_from_previous = True
    trains_members = True

    def __init__(self, *, encoder: Mapping, field: Mapping, grad: Mapping, sampler: Mapping, loss: Mapping,
                 train: Mapping, metrics: Mapping, seed: int, label: str, data_term: Optional[Mapping] = None):
        super().__init__(iterations=train["iterations"], eval_every=train["eval_every"], metrics=metrics, seed=seed,
                         label=label)
        self.rays_per_batch = int(train["rays_per_batch"])
        if self.rays_per_batch < 1:
            raise ValueError(f"rays per batch must be at least 1, got {self.rays_per_batch}")
        check_views_per_batch(train["views_per_batch"])
        self.views_per_batch = train["views_per_batch"]
        self.stop_tol = train["stop_when_converged"]
        if self.stop_tol is not None and not 0.0 < float(self.stop_tol) < 1.0:
            raise ValueError(f"train.stop_when_converged={self.stop_tol}: a relative improvement within (0, 1), or null")
        self.stop_patience = int(train["stop_patience"])
        if self.stop_patience < 1:
            raise ValueError(f"train.stop_patience={self.stop_patience}: at least 1 evaluation")
        self.outside_fraction = float(train["outside_fraction"])
        if not 0.0 <= self.outside_fraction < 1.0:
            raise ValueError(f"outside_fraction must be within [0, 1), got {self.outside_fraction}")
        self.weights = {k: float(v) for k, v in grad["weights"].items()}
        self.stencil = grad["stencil"]
        if self.stencil not in ("axes", "across"):
            raise ValueError(f"grad.stencil must be 'axes' or 'across', got '{self.stencil}'")
        if not any(w > 0 for w in self.weights.values()):
            raise ValueError("every gradient-loss weight is zero: nothing to train on (set grad.weights)")
        check_faces(loss["ambient_faces"])
        check_faces(loss["ambient_fallback"], "loss.ambient_fallback", auto=False)
        self.encoder = ENCODERS.build(encoder)
        self.sampler = SAMPLERS.build(sampler)
        self.data_term = DATA_TERMS.build(data_term or {"name": "flow"})
        self.hidden, self.prior = tuple(field["hidden"]), field["prior"]
        self.table_decay = float(train["table_decay"])
        self.init_volume, self.init_iterations = train["init_volume"], int(train["init_iterations"])
        self.ema_decay = float(train["ema_decay"])
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"train.ema_decay={self.ema_decay}: a decay within [0, 1) (0: no average)")
        if self.table_decay < 0:
            raise ValueError(f"train.table_decay={self.table_decay}: a decay rate of at least 0")
        if self.init_volume is not None and not Path(self.init_volume).expanduser().is_file():
            raise FileNotFoundError(f"train.init_volume: volume file {self.init_volume} does not exist")
        self.loss_cfg = dict(loss)
        self.optim_cfg = {k: train[k] for k in ("lr", "betas", "eps", "lr_min")}
        self.labels.update(encoder=encoder["name"], grad=grad["name"])

    def setup(self, scene: Scene, masks) -> "NeuralSolver":
        """The field on the scene's probe box (gated by ``masks.gate``), its optimiser, and the ray pools training
        draws from (``masks.inside``)."""
        super().setup(scene, masks)
        self.interval = prior = prior_interval(self.prior, scene.sigma_prior)  # the field's sigma bounds (a, b)
        self.prior_source = prior_source(self.prior, scene.sigma_prior_from if scene.sigma_prior else None)
        check_truth_within(scene.truth_T, scene.ambient, prior, self.prior_source)
        self.field = NeuralField(self.encoder, scene.box, hidden=self.hidden, prior=prior, gate=masks.gate)
        self.field.to(self.device)
        self.sampler.to(self.device)
        with torch.no_grad():  # builds (first run on a machine) or loads the encoder's compiled kernels now, in setup
            self.field.network(torch.zeros(1, 3, device=self.device))
        lc = self.loss_cfg
        faces = self.resolve_ambient_faces(lc["ambient_faces"], masks, lc["crossed_cover"], lc["ambient_fallback"])
        b = AmbientBoundary(scene.box, faces, lc["ambient_weight"], lc["ambient_points"])
        self.boundary = b if b.active else None
        self.generator = torch.Generator(self.device).manual_seed(self.seed)
        self.batches = RayBatcher(scene, masks.inside, self.rays_per_batch, self.views_per_batch,
                                  self.outside_fraction, self.generator)
        self.data_term.setup(scene, self.batches, self.iterations, masks)
        self.plan = StagePlan(self.data_term.stages())
        self.iterations, self.previous = self.plan.iterations, None  # previous: the field the chooser competes with
        if self.data_term.fitted != "flow":
            self.labels["data_term"] = self.data_term.fitted
        for stage, end in zip(self.plan.stages, self.plan.ends):
            if stage.name != "flow":
                self.report[f"{stage.name}_from_iteration"] = end - stage.iterations
        rms = float(scene.eps[self.batches.inside()].double().norm(dim=-1).pow(2).mean().sqrt()) / scene.scale
        tv = TotalVariation(scene.box, lc["tv_weight"], lc["tv_points"], rms)
        self.tv = tv if tv.active else None
        self.optimizer = self._optimizer()
        self.scheduler = self.plan.cosine(self.optimizer, 0, self.optim_cfg["lr_min"])
        if self.init_volume is not None:
            self._warm_start(self.init_volume)
        self.average = averaged_field(self.field, self.ema_decay, self.rate) if self.ema_decay > 0 else None
        # central-difference step: b_min / (2 K), K the most samples per ray
        self.renderer = DeflectionRenderer(self.weights, self.stencil,
                                           scene.box.shortest_side_mm / (2 * self.sampler.samples_per_ray),
                                           scene.perpendicular_only, self.sampler.samples_per_ray)
        self.samples_seen = 0
        self.rays_seen = 0
        self.samples_max = 0
        self.rays_skipped = 0
        return self

    def _optimizer(self) -> torch.optim.AdamW:
        """AdamW on the field (the encoder's tables with ``train.table_decay``, the rest without) and the data
        term's own parameters, at ``train.lr``."""
        oc = self.optim_cfg
        enc = list(self.field.encoder.parameters())
        rest = [p for p in self.field.parameters() if all(p is not q for q in enc)]
        groups = [{"params": rest, "weight_decay": 0.0}] + ([{"params": enc, "weight_decay": self.table_decay}]
                                                            if enc else []) + self.data_term.parameter_groups()
        return torch.optim.AdamW(groups, lr=oc["lr"], betas=tuple(oc["betas"]), eps=oc["eps"],
                                 fused=self.device.type == "cuda")

    def _end_of_stage(self) -> None:
        """Where a stage ends and another begins: the field it leaves and what that leaves of the held-out views,
        where the last stage's field will compete with it; the next stage's learning-rate schedule where it starts
        one of its own."""
        ending = self.plan.ending(self.iteration)
        if ending is None:
            return
        if ending is self.plan.before_chooser and self.scene.heldout is not None:
            weights = {k: v.detach().clone() for k, v in self.estimate.state_dict().items()}
            self.previous = {"weights": weights, "figures": self.evaluation.stage_figures(
                self.predict, self.reconstruction, self.data_term)}
        if self.plan.restarts(self.iteration):
            self.scheduler = self.plan.cosine(self.optimizer, self.iteration, self.optim_cfg["lr_min"])

    def choose_by_heldout(self) -> Optional[str]:
        """At the end of a run whose last stage chooses (:attr:`Stage.choose`; the images' after the flow's): keeps
        the field the held-out views prefer (:func:`nerif.solvers.stages.choose`), putting back the one the stage
        before it left where that one explains them better; records the choice in :attr:`report` and returns the
        name of the stage whose field it kept (None where nothing was chosen: no such stage, no held-out view, or
        not finished)."""
        last, before = self.plan.chooser, self.plan.before_chooser
        if last is None or self.iteration < self.iterations or "data_term_kept" in self.report:
            return None
        if self.previous is None:
            log.info("data_term=images: no held-out view to choose between the %s and the %s fields by; the %s is "
                     "kept", whose(before.name), whose(last.name), whose(last.name))
            return None
        figures = self.evaluation.stage_figures(self.predict, self.reconstruction, self.data_term)
        kept, report = choose(before, last, self.previous["figures"], figures, self.evaluation.physical)
        self.report.update(report)
        if kept == before.name:
            self.estimate.load_state_dict(self.previous["weights"])
            self.field.load_state_dict(self.previous["weights"])
        return kept

    def fit(self, **kwargs) -> dict:
        """:meth:`IterativeSolver.fit`, then the held-out views' choice between the last two stages' fields
        (:meth:`choose_by_heldout`); where they keep the earlier one, the last evaluation and the checkpoint are of
        it."""
        last = super().fit(**kwargs)
        chooser = self.plan.chooser
        if chooser is not None and self.choose_by_heldout() not in (None, chooser.name):
            self.history.pop()
            last = self.evaluate()
            if kwargs.get("checkpoint") is not None and kwargs.get("checkpoint_at_end", True):
                self.checkpoint(kwargs["checkpoint"])
        return last

    def member(self, views: list[int], iterations: int, seed: int, lr_factor: float,
               perturb: float = 0.0) -> "NeuralSolver":
        """An ensemble's member, a new solver made from this one's trained state (which it leaves as it is): the
        field evaluations use (the kept one), its encoder's tables perturbed by Gaussian noise of ``perturb`` times
        each table's RMS (what the data pin down is pulled back by the training, what they leave free stays
        perturbed), to be trained (:meth:`train`) for ``iterations`` more steps on the observed deflections (the
        flow's term, noise-weighted as set) of the training ``views`` only, with its own optimiser, cosine schedule
        from ``lr_factor`` of each group's peak rate, average and random draws (``seed``). The scene, masks and
        evaluation are shared, read only: members can train side by side."""
        m = copy.copy(self)
        m.field = copy.deepcopy(self.field)
        m.field.load_state_dict({k: v.detach().clone() for k, v in self.estimate.state_dict().items()})
        m.sampler = copy.deepcopy(self.sampler)
        m.generator = torch.Generator(self.device).manual_seed(int(seed))
        if perturb > 0:
            with torch.no_grad():
                for p in m.field.encoder.parameters():
                    noise = torch.randn(p.shape, generator=m.generator, device=p.device, dtype=p.dtype)
                    p.add_(noise * (perturb * p.pow(2).mean().sqrt()))
        flow = getattr(self.data_term, "flow", self.data_term)  # the image term's own flow term, or the flow term
        term = DATA_TERMS.build({"name": "flow", "noise_weighted": flow.noise_weighted})
        m.data_term = term.setup(self.scene, self.batches.of_views(views, m.generator), iterations)
        m.plan = StagePlan([Stage("flow", m.data_term, iterations, lr=lr_factor)], start=self.iteration)
        m.iterations, m.previous = m.plan.iterations, None
        m.optimizer = m._optimizer()
        m.scheduler = m.plan.cosine(m.optimizer, m.iteration, self.optim_cfg["lr_min"])
        m.average = averaged_field(m.field, self.ema_decay, m.rate) if self.average is not None else None
        m.history, m.step_times, m.report, m.labels = [], [], {}, dict(self.labels)
        return m

    def train(self, stop=None) -> bool:
        """Steps to :attr:`iterations` without evaluations or checkpoints (an ensemble's member); ``stop()`` true ends
        it between steps. Returns whether it ran to the end."""
        while self.iteration < self.iterations:
            if stop is not None and stop():
                return False
            self.step()
        return True

    def _warm_start(self, path: str) -> None:
        """Fit the field to the sigma volume of ``path`` (a ``reconstruction.npz`` of any solver on this probe
        grid, key ``sigma``) before training on rays."""
        vol = read_volume(path, "train.init_volume", key="sigma")
        if vol.shape != tuple(self.scene.box.shape):
            raise ValueError(f"train.init_volume {path}: shape {vol.shape}, but the probe grid is "
                             f"{tuple(self.scene.box.shape)}")
        a, b = self.interval
        lo, hi = float(vol.min()), float(vol.max())
        if lo < a - 0.5 * (b - a) or hi > b + 0.5 * (b - a):  # a temperature [K], or another quantity
            what = " (a temperature in kelvin?)" if lo > 100 else ""
            raise ValueError(f"train.init_volume {path} holds values {lo:.4g} to {hi:.4g}{what}, far outside the "
                             f"field's sigma interval [{a:g}, {b:g}]: give a reconstruction.npz of nerif (its sigma "
                             "is read)")
        t0 = time.perf_counter()
        rms = fit_to_volume(self.field, self.scene.box, torch.as_tensor(vol, device=self.device),
                            self.init_iterations, generator=self.generator)
        self.train_seconds += time.perf_counter() - t0
        log.info("warm start: the field fits %s to %.3g (RMS sigma) after %d iterations", path, rms,
                 self.init_iterations)

    def saturation(self, sigma: np.ndarray, failed: str = "") -> dict:
        """:func:`nerif.field.prior_saturation` of ``sigma`` within this field's prior (``failed``: the held-out
        views' sentence where they say the fit failed)."""
        return prior_saturation(sigma, self.interval, self.scene.ambient, self.scene.truth_T, failed, self.prior_source)

    # --- optimisation ---
    def batch_loss(self, update_occupancy: bool = True) -> tuple[dict, object]:
        """The loss of the next batch of the stage that holds :attr:`iteration` (its rays drawn from
        :attr:`generator`, the occupancy grid updated first where it is due and ``update_occupancy``), with its graph
        to the field's parameters: ``loss`` (the weighted sum), ``loss_<term>`` of the data term, ``loss_boundary``,
        ``loss_tv``; and the samples."""
        if update_occupancy:
            self.sampler.update(self.scene.box, self.occupancy_value, self.iteration, self.generator)
        stage = self.plan.at(self.iteration)
        batch = stage.term.draw(self.iteration)
        samples = self.sampler(self.scene.box, batch.origins, batch.dirs, self.generator)
        eps = self.renderer.train(self.field, samples, batch.dirs)
        terms = stage.term.terms(eps, batch, self.iteration)
        loss = weighted_sum(terms, self.weights)
        named = {f"loss_{n}": t for n, t in terms.items()}
        for name, term in (("boundary", self.boundary), ("tv", self.tv)):
            value = term(self.field, self.generator) if term is not None else None
            if value is not None:
                loss = loss + value
                named[f"loss_{name}"] = value
        return {"loss": loss, **named}, samples

    def step(self) -> dict:
        """One iteration on the next views (:meth:`RayBatcher.views`); returns the loss terms (floats)."""
        t0 = time.perf_counter()
        named, samples = self.batch_loss()
        loss = named["loss"]
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.scheduler.step()
        per_ray = samples.per_ray
        # every number of the step in one transfer: one wait for the device per step, not one per number
        stats = torch.stack([t.detach().float() for t in named.values()] +
                            [per_ray.max().float(), (per_ray == 0).sum().float()]).tolist()
        out = dict(zip(named, stats[:len(named)]))
        if not math.isfinite(out["loss"]):  # the step that made it is never saved: fit keeps the last checkpoint
            raise DivergenceError(f"the loss became {out['loss']} at iteration {self.iteration}: the run diverged "
                                  "(try a lower train.lr)")
        if self.average is not None:
            self.average.update_parameters(self.field)
        self._timed(time.perf_counter() - t0)
        self._end_of_stage()
        self.samples_seen += len(samples.positions)
        self.rays_seen += samples.n_rays
        self.samples_max = max(self.samples_max, int(stats[-2]))
        self.rays_skipped += int(stats[-1])
        out.update(lr=self.optimizer.param_groups[0]["lr"],
                   samples_per_ray=len(samples.positions) / max(samples.n_rays, 1),
                   rays_skipped=stats[-1] / max(samples.n_rays, 1))
        return out

    def shakes_px(self) -> Optional[torch.Tensor]:
        """The shakes the image term refined with the field (``data_term.shake_lr``), else None."""
        return self.data_term.shakes_px()

    def occupancy_value(self, positions: torch.Tensor) -> torch.Tensor:
        """(N, 3) [mm] -> (N,) |sigma| of the trained field: what the occupancy grid thresholds."""
        return self.field(positions).abs()

    def rate(self) -> float:
        """The learning rate of the next step over its peak (``train.lr``), from 1 down to ``lr_min / lr``."""
        return self.optimizer.param_groups[0]["lr"] / self.scheduler.base_lrs[0]

    # --- evaluation ---
    @property
    def estimate(self) -> NeuralField:
        """The field that evaluations and outputs use: the average of the trained weights (``train.ema_decay``)
        once a step has updated it, else the trained field itself."""
        if self.average is None or int(self.average.n_averaged) == 0:
            return self.field
        return self.average.module

    def reconstruction(self) -> np.ndarray:
        """sigma on the scene's probe grid, (nx, ny, nz)."""
        return self.estimate.on_grid(self.scene.box).cpu().numpy().astype(np.float64)

    def render(self, o: torch.Tensor, d: torch.Tensor, operators=("auto", "discrete")) -> dict:
        """Deflections of sigma of rays (R, 3) by each operator, without any parameter graph."""
        return self.renderer.evaluate(self.estimate, self.scene.box, o, d, operators)

    def predict(self, origins: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """Deflections of sigma by the operator training fits (:attr:`DeflectionRenderer.fitted_operator`)."""
        op = self.renderer.fitted_operator
        return self.render(origins, dirs, (op,))[op]

    def evaluate(self) -> dict:
        """Metrics now: temperature/sigma errors on the grid (when the truth is known), deflection errors."""
        ev = self.evaluation
        m = {"iteration": self.iteration, "wall_time_s": self.train_seconds, **ev.field_errors(self.reconstruction()),
             **ev.deflection_errors(self.render(*ev.train_rays()))}
        m["deflection_rmse"] = m[f"deflection_rmse_{self.renderer.fitted_operator}"]
        m.update(ev.heldout_errors(self.predict))
        self.history.append(m)
        rmses = [h["deflection_rmse"] for h in self.history]
        if self.stop_tol is not None and len(rmses) > self.stop_patience:
            # the best of the last `patience` evaluations against the best before them: one noisy evaluation
            # (Adam early on, one view's batch) does not stop a run
            before, recent = min(rmses[:-self.stop_patience]), min(rmses[-self.stop_patience:])
            self.converged = recent > (1.0 - float(self.stop_tol)) * before
        return m

    # --- checkpoints ---
    def state_dict(self) -> dict:
        return {**super().state_dict(), "field": self.field.state_dict(), "optimizer": self.optimizer.state_dict(),
                "average": None if self.average is None else self.average.state_dict(),
                "sampler": self.sampler.state_dict(), "scheduler": self.scheduler.state_dict(),
                "generator": self.generator.get_state(), "samples_seen": self.samples_seen, "rays_seen": self.rays_seen,
                "samples_max": self.samples_max, "rays_skipped": self.rays_skipped, "converged": self.converged,
                "data_term": self.data_term.state_dict(), "previous_stage": self.previous}

    def _load_field(self, st: dict, weights: Optional[dict] = None) -> None:
        try:
            self.field.load_state_dict(st["field"] if weights is None else weights)
        except RuntimeError as e:
            raise ValueError("the checkpoint was made with another field configuration (encoder/field settings "
                             f"differ): {str(e).splitlines()[0]}") from None
        try:
            self.sampler.load_state_dict(st.get("sampler", {}))
        except RuntimeError as e:
            raise ValueError("the checkpoint was made with another sampler (sampler= or "
                             f"field.occupancy_resolution differ): {str(e).splitlines()[0]}") from None

    def start_from(self, path: Path) -> None:
        """The previous frame's result (its averaged weights, or its trained ones when it kept no average) and
        occupancy grid, from ``path`` (that frame's checkpoint); the optimiser, its schedule, the average and the
        counters start afresh. The 3-D mask stays this frame's own."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"the previous frame's checkpoint {path} does not exist")
        st = torch.load(path, map_location=self.device, weights_only=False)
        average = st.get("average")
        weights = None
        if average is not None and int(average["n_averaged"]) > 0:
            weights = {k[len("module."):]: v for k, v in average.items() if k.startswith("module.")}
        self._load_field(st, weights)

    def load_state_dict(self, st: dict) -> None:
        self._load_field(st)
        self.data_term.load_state_dict(st.get("data_term", {}))
        try:
            self.optimizer.load_state_dict(st["optimizer"])
        except ValueError as e:
            raise ValueError("the checkpoint's optimiser state does not fit this solver (made by a nerif before "
                             f"train.table_decay, or with another encoder): {str(e).splitlines()[0]}") from None
        self.previous = st.get("previous_stage", st.get("flow_stage"))
        self.scheduler.load_state_dict(st["scheduler"])
        self.plan.replan(self.scheduler, self.optimizer, int(st["iteration"]))
        if self.average is not None:
            if st.get("average") is not None:
                self.average.load_state_dict(st["average"])
            else:  # a checkpoint without an average: it starts again from the next step's weights
                self.average.n_averaged.zero_()
        self.generator.set_state(st["generator"].cpu() if self.device.type == "cpu" else st["generator"])
        super().load_state_dict(st)
        for k in ("samples_seen", "rays_seen", "samples_max", "rays_skipped"):
            setattr(self, k, st[k])
        self.converged = bool(st.get("converged", False))

    def timing(self) -> dict:
        return {**super().timing(), "samples_per_second": self.samples_seen / max(self.train_seconds, 1e-9),
                "field_evaluations_per_sample": self.renderer.evaluations_per_sample,
                "samples_per_ray_mean": self.samples_seen / max(self.rays_seen, 1), "samples_per_ray_max": self.samples_max,
                "rays_skipped_fraction": self.rays_skipped / max(self.rays_seen, 1)}
