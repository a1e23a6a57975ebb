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
from nerif.field import NeuralField, check_truth_within, perturb_tables, prior_interval, prior_saturation, prior_source
from nerif.losses import AmbientBoundary, TotalVariation, weighted_sum
from nerif.renderers import SAMPLERS, DeflectionRenderer
from nerif.solvers.base import SOLVERS, DivergenceError, IterativeSolver, check_faces
from nerif.solvers.batches import RayBatcher
from nerif.solvers.data_terms import DATA_TERMS
from nerif.solvers.poses import POSES, log_refined
from nerif.solvers.stages import HeldoutChoice, Stage, StagePlan
from nerif.solvers.training import Optimisation, SampleCounts, Training, allocations, warm_start
from nerif.units import stage_key

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
        train: ``iterations``, ``eval_every`` (:class:`IterativeSolver`) and the rest: :class:`Training`.
        metrics, seed, label: see :class:`IterativeSolver`.
    """

    name = "nerif"
    allocations = staticmethod(allocations)
    starts_from_previous = True

    def __init__(self, *, encoder: Mapping, field: Mapping, grad: Mapping, sampler: Mapping, loss: Mapping,
                 train: Mapping, metrics: Mapping, seed: int, label: str, data_term: Optional[Mapping] = None,
                 poses: Optional[Mapping] = None):
        super().__init__(iterations=train["iterations"], eval_every=train["eval_every"], metrics=metrics, seed=seed,
                         label=label)
        self.training = Training.read(train)
        self.weights = {k: float(v) for k, v in grad["weights"].items()}
        self.stencil = grad["stencil"]
        DeflectionRenderer.check(self.weights, self.stencil)
        check_faces(loss["ambient_faces"])
        check_faces(loss["ambient_fallback"], "loss.ambient_fallback", auto=False)
        self.encoder = ENCODERS.build(encoder)
        self.sampler = SAMPLERS.build(sampler)
        self.data_term = DATA_TERMS.build(data_term or {"name": "flow"})
        self.poses = POSES.build(poses or {"name": "given"})
        self.hidden, self.prior = tuple(field["hidden"]), field["prior"]
        self.loss_cfg = dict(loss)
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
        t = self.training
        self.batches = RayBatcher(scene, masks.inside, t.rays_per_batch, t.views_per_batch, t.outside_fraction,
                                  self.generator)
        self.data_term.setup(scene, self.batches, self.iterations, masks)
        self.plan = StagePlan(self.data_term.stages())
        self.iterations = self.plan.iterations
        self.poses.setup(scene, self.iterations)
        figures = (lambda: self.evaluation.stage_figures(self.predict, self.reconstruction, self.data_term))
        self.choice = HeldoutChoice(self.plan, figures if scene.heldout is not None else None, self.evaluation.physical)
        if self.data_term.fitted != "flow":
            self.labels["data_term"] = self.data_term.fitted
        for stage, end in zip(self.plan.stages, self.plan.ends):
            if stage.name != "flow":
                self.report[stage_key(stage.name, "from_iteration")] = end - stage.iterations
        rms = float(scene.eps[self.batches.inside()].double().norm(dim=-1).pow(2).mean().sqrt()) / scene.scale
        tv = TotalVariation(scene.box, lc["tv_weight"], lc["tv_points"], rms)
        self.tv = tv if tv.active else None
        if t.init_volume is not None:
            t0 = time.perf_counter()
            warm_start(self.field, scene.box, t.init_volume, prior, t.init_iterations, self.generator)
            self.train_seconds += time.perf_counter() - t0
        self.optimisation = Optimisation(self.field, self.data_term.parameter_groups(), t, self.plan, 0)
        # central-difference step: b_min / (2 K), K the most samples per ray
        self.renderer = DeflectionRenderer(self.weights, self.stencil,
                                           scene.box.shortest_side_mm / (2 * self.sampler.samples_per_ray),
                                           scene.perpendicular_only, self.sampler.samples_per_ray)
        self.counts = SampleCounts()
        return self

    def choose_by_heldout(self) -> Optional[str]:
        """At the end of a run whose last stage chooses: the field the held-out views prefer kept
        (:meth:`HeldoutChoice.settle`), the choice in :attr:`report`; the name of the stage whose field it kept (None
        where nothing was chosen or the run has not finished)."""
        if self.iteration < self.iterations or "data_term_kept" in self.report:
            return None
        return self.choice.settle(self.report, (self.estimate, self.field))

    def fit(self, **kwargs) -> dict:
        """:meth:`IterativeSolver.fit`, then the held-out views' choice (:meth:`choose_by_heldout`): where they keep
        the earlier stage's field, the last evaluation and the checkpoint are of it; the refined poses reported."""
        last = super().fit(**kwargs)
        chooser = self.plan.chooser
        if chooser is not None and self.choose_by_heldout() not in (None, chooser.name):
            self.history.pop()
            last = self.evaluate()
            if kwargs.get("checkpoint") is not None and kwargs.get("checkpoint_at_end", True):
                self.checkpoint(kwargs["checkpoint"])
        found = self.poses.report()  # the refined poses, where they are
        self.report.update(found)
        log_refined(found)
        return last

    def clone(self, views: list[int], seed: int, *, iterations: int = 0, lr_factor: float = 1.0,
              perturb: float = 0.0) -> "NeuralSolver":
        """:meth:`nerif.solvers.trained.TrainedField.clone` of the field evaluations use (the kept one): its
        encoder's tables perturbed by ``perturb`` times each table's RMS (:func:`nerif.field.perturb_tables`), trained
        on the flow's term of ``views`` (:meth:`DeflectionTerm.for_member`) with its own optimiser, schedule, average
        and draws. The scene, masks and evaluation are shared, read only: clones can train side by side."""
        m = copy.copy(self)
        m.field = copy.deepcopy(self.field)
        m.field.load_state_dict({k: v.detach().clone() for k, v in self.estimate.state_dict().items()})
        m.sampler = copy.deepcopy(self.sampler)
        m.generator = torch.Generator(self.device).manual_seed(int(seed))
        if perturb > 0:
            perturb_tables(m.field, perturb, m.generator)
        steps = max(int(iterations), 1)  # a plan of at least one step; a clone never trained keeps its state
        m.data_term = self.data_term.for_member().setup(self.scene, self.batches.of_views(views, m.generator), steps)
        m.plan = StagePlan([Stage("flow", m.data_term, steps, lr=lr_factor)], start=self.iteration)
        m.iterations, m.choice = m.plan.iterations, HeldoutChoice(m.plan, None, False)
        m.optimisation = Optimisation(m.field, m.data_term.parameter_groups(), self.training, m.plan, m.iteration)
        m.history, m.step_times, m.report, m.labels = [], [], {}, dict(self.labels)
        m.counts = copy.copy(self.counts)
        return m

    def parameters(self) -> list[torch.Tensor]:
        """The field's trained tensors (:meth:`nerif.solvers.trained.TrainedField.parameters`)."""
        return [p for p in self.field.parameters() if p.requires_grad]

    def saturation(self, sigma: np.ndarray, failed: str = "") -> dict:
        """:func:`nerif.field.prior_saturation` of ``sigma`` within this field's prior (``failed``: the held-out
        views' sentence where they say the fit failed)."""
        return prior_saturation(sigma, self.interval, self.scene.ambient, self.scene.truth_T, failed, self.prior_source)

    # --- optimisation ---
    def batch_loss(self, update_occupancy: bool = True) -> tuple[dict, object]:
        """The next batch's loss (the stage that holds :attr:`iteration`; the occupancy grid updated first where due
        and ``update_occupancy``) with its graph to the field: ``loss``, ``loss_<term>``, ``loss_boundary``,
        ``loss_tv``; and the samples."""
        if update_occupancy:
            # the occupancy grid thresholds |sigma| of the trained field
            self.sampler.update(self.scene.box, lambda x: self.field(x).abs(), self.iteration, self.generator)
        stage = self.plan.at(self.iteration)
        batch = stage.term.draw(self.iteration)
        origins, dirs, turn = self.poses.rays(batch.origins, batch.dirs)
        samples = self.sampler(self.scene.box, origins, dirs, self.generator)
        eps = self.poses.back(self.renderer.train(self.field, samples, dirs), turn)
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
        self.optimisation.step(named["loss"])
        per_ray = samples.per_ray
        # every number of the step in one transfer: one wait for the device per step, not one per number
        stats = torch.stack([t.detach().float() for t in named.values()] +
                            [per_ray.max().float(), (per_ray == 0).sum().float()]).tolist()
        out = dict(zip(named, stats[:len(named)]))
        if not math.isfinite(out["loss"]):  # the step that made it is never saved: fit keeps the last checkpoint
            raise DivergenceError(f"the loss became {out['loss']} at iteration {self.iteration}: the run diverged "
                                  "(try a lower train.lr)")
        self.optimisation.after_step(self.iteration + 1)
        if self.poses.due(self.iteration + 1):
            op = self.renderer.fitted_operator
            self.poses.fit(lambda o, d: self.renderer.evaluate(self.estimate, self.scene.box, o, d, (op,))[op])
        self._timed(time.perf_counter() - t0)
        self.choice.after_step(self.iteration, lambda: self.estimate)
        self.counts.add(len(samples.positions), samples.n_rays, int(stats[-2]), int(stats[-1]))
        out.update(lr=self.optimisation.lr,
                   samples_per_ray=len(samples.positions) / max(samples.n_rays, 1),
                   rays_skipped=stats[-1] / max(samples.n_rays, 1))
        return out

    def shakes_px(self) -> Optional[torch.Tensor]:
        """The shakes the image term refined with the field (``data_term.shake_lr``), else None."""
        return self.data_term.shakes_px()

    # --- evaluation ---
    @property
    def estimate(self) -> NeuralField:
        """The field that evaluations and outputs use (:attr:`Optimisation.estimate`)."""
        return self.optimisation.estimate

    @property
    def cell_mm(self) -> float:
        return self.field.finest_cell_mm

    def reconstruction(self) -> np.ndarray:
        """sigma on the scene's probe grid, (nx, ny, nz)."""
        return self.estimate.on_grid(self.scene.box).cpu().numpy().astype(np.float64)

    def render(self, o: torch.Tensor, d: torch.Tensor, operators=("auto", "discrete")) -> dict:
        """Deflections of sigma of rays (R, 3) by each operator, without any parameter graph; a training view's
        rays where its pose is refined (:mod:`nerif.solvers.poses`), in the frame its camera measured them."""
        o, d, turn = self.poses.rays(o, d)
        return self.poses.back(self.renderer.evaluate(self.estimate, self.scene.box, o, d, operators), turn)

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
        converged = self.training.converged([h["deflection_rmse"] for h in self.history])
        self.converged = self.converged if converged is None else converged
        return m

    # --- checkpoints ---
    def state_dict(self) -> dict:
        return {**super().state_dict(), **self.optimisation.state_dict(), **self.counts.state_dict(),
                "field": self.field.state_dict(), "sampler": self.sampler.state_dict(),
                "generator": self.generator.get_state(), "converged": self.converged,
                "data_term": self.data_term.state_dict(), "poses": self.poses.state_dict(),
                "previous_stage": self.choice.previous}

    def _load_field(self, st: dict, weights: Optional[dict] = None) -> None:
        self.field.load_checked(st["field"] if weights is None else weights)
        try:
            self.sampler.load_state_dict(st.get("sampler", {}))
        except RuntimeError as e:
            raise ValueError("the checkpoint was made with another sampler (sampler= or "
                             f"field.occupancy_resolution differ): {str(e).splitlines()[0]}") from None

    def start_from(self, path: Path) -> None:
        """The previous frame's result (its averaged weights, else its trained ones) and occupancy grid from its
        checkpoint ``path``; the optimiser, schedule, average and counters afresh, the 3-D mask this frame's own."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"the previous frame's checkpoint {path} does not exist")
        st = torch.load(path, map_location=self.device, weights_only=False)
        self._load_field(st, Optimisation.averaged_weights(st))

    def load_state_dict(self, st: dict) -> None:
        self._load_field(st)
        self.data_term.load_state_dict(st.get("data_term", {}))
        self.poses.load_state_dict(st.get("poses", {}))
        self.optimisation.load_state_dict(st, int(st["iteration"]))
        self.choice.previous = st.get("previous_stage", st.get(stage_key("flow")))
        self.generator.set_state(st["generator"].cpu() if self.device.type == "cpu" else st["generator"])
        super().load_state_dict(st)
        self.counts.load_state_dict(st)
        self.converged = bool(st.get("converged", False))

    def timing(self) -> dict:
        return {**super().timing(), **self.counts.figures(self.train_seconds),
                "field_evaluations_per_sample": self.renderer.evaluations_per_sample}
