"""The neural solver (``solver=nerif``): a neural field trained on a scene's deflections, its optimisation state
and its steps."""
from __future__ import annotations

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
from nerif.field import NeuralField, averaged_field, fit_to_volume, prior_interval
from nerif.losses import AmbientBoundary, TotalVariation, deflection_terms, weighted_sum
from nerif.metrics import deflection_rmse
from nerif.renderers import SAMPLERS, render_deflections
from nerif.renderers.samplers import UniformSampler
from nerif.solvers.base import SOLVERS, DivergenceError, IterativeSolver, check_faces, fixed_rays

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

    def __init__(self, *, encoder: Mapping, field: Mapping, grad: Mapping, sampler: Mapping, loss: Mapping,
                 train: Mapping, metrics: Mapping, seed: int, label: str):
        super().__init__(iterations=train["iterations"], eval_every=train["eval_every"], metrics=metrics, seed=seed,
                         label=label)
        self.rays_per_batch = int(train["rays_per_batch"])
        if self.rays_per_batch < 1:
            raise ValueError(f"rays per batch must be at least 1, got {self.rays_per_batch}")
        k = train["views_per_batch"]
        if not (k == "all" or (isinstance(k, int) and not isinstance(k, bool) and k >= 1)):
            raise ValueError(f"train.views_per_batch must be a number of views (at least 1) or 'all', got {k!r}")
        self.views_per_batch = k
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
        self._check_truth_within(prior)
        self.field = NeuralField(self.encoder, scene.box, hidden=self.hidden, prior=prior, gate=masks.gate)
        self.field.to(self.device)
        with torch.no_grad():  # builds (first run on a machine) or loads the encoder's compiled kernels now, in setup
            self.field.network(torch.zeros(1, 3, device=self.device))
        lc = self.loss_cfg
        faces = self.resolve_ambient_faces(lc["ambient_faces"], masks, lc["crossed_cover"], lc["ambient_fallback"])
        b = AmbientBoundary(scene.box, faces, lc["ambient_weight"], lc["ambient_points"])
        self.boundary = b if b.active else None
        self.pools = self._pools(scene, masks.inside, self.outside_fraction)
        inside = torch.cat([pool[0] for pool in self.pools])
        rms = float(scene.eps[inside].double().norm(dim=-1).pow(2).mean().sqrt()) / scene.ambient.delta_thre
        tv = TotalVariation(scene.box, lc["tv_weight"], lc["tv_points"], rms)
        self.tv = tv if tv.active else None
        oc = self.optim_cfg
        fused = self.device.type == "cuda"
        enc = list(self.field.encoder.parameters())
        rest = [p for p in self.field.parameters() if all(p is not q for q in enc)]
        groups = [{"params": rest, "weight_decay": 0.0}] + ([{"params": enc, "weight_decay": self.table_decay}]
                                                            if enc else [])
        self.optimizer = torch.optim.AdamW(groups, lr=oc["lr"], betas=tuple(oc["betas"]), eps=oc["eps"], fused=fused)
        self.scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(self.optimizer, T_max=self.iterations,
                                                                    eta_min=oc["lr_min"])
        self.generator = torch.Generator(self.device).manual_seed(self.seed)
        if self.init_volume is not None:
            self._warm_start(self.init_volume)
        self.average = averaged_field(self.field, self.ema_decay, self.rate) if self.ema_decay > 0 else None
        # central-difference step: b_min / (2 K), K the most samples per ray
        self.step_mm = scene.box.shortest_side_mm / (2 * self.sampler.samples_per_ray)
        self.scale = scene.ambient.delta_thre  # rad per unit of sigma deflection
        self.samples_seen = 0
        self.rays_seen = 0
        self.samples_max = 0
        self.rays_skipped = 0
        self._eval_index = fixed_rays(scene, self.eval_rays_per_view, self.seed + 1)
        self._eval_sampler = UniformSampler(self.sampler.samples_per_ray, jitter=False)
        return self

    def _warm_start(self, path: str) -> None:
        """Fit the field to the sigma volume of ``path`` (a ``reconstruction.npz`` of any solver on this probe
        grid, key ``sigma``) before training on rays."""
        vol = read_volume(path, "train.init_volume", key="sigma")
        if vol.shape != tuple(self.scene.box.shape):
            raise ValueError(f"train.init_volume {path}: shape {vol.shape}, but the probe grid is "
                             f"{tuple(self.scene.box.shape)}")
        t0 = time.perf_counter()
        rms = fit_to_volume(self.field, self.scene.box, torch.as_tensor(vol, device=self.device),
                            self.init_iterations, generator=self.generator)
        self.train_seconds += time.perf_counter() - t0
        log.info("warm start: the field fits %s to %.3g (RMS sigma) after %d iterations", path, rms,
                 self.init_iterations)

    def _check_truth_within(self, prior: tuple[float, float]) -> None:
        """Refuse a known truth that the field cannot represent (hotter than its prior's bound allows)."""
        amb = self.scene.ambient
        if self.scene.truth_T is None or not amb.temperature_known:
            return
        sigma = amb.sigma_from_temperature(self.scene.truth_T)
        if sigma.min() < prior[0] - 1e-6 or sigma.max() > prior[1] + 1e-6:
            hottest = float(self.scene.truth_T.max())
            bound = float(amb.temperature_from_sigma(np.float64(prior[0])))
            raise ValueError(f"the true field reaches {hottest:.0f} K, beyond what the field can represent with "
                             f"data.T_max={amb.T_max:g} K (up to {bound:.0f} K at the prior's bound sigma = "
                             f"{prior[0]:g}): set data.T_max={np.ceil(hottest / 50) * 50:.0f} or higher")

    def saturation(self, sigma: np.ndarray) -> dict:
        """Share of the flame (voxels with sigma below -0.05) within 1 % of the prior's lower bound, and
        ``warnings`` when it is over 1 %: the flame may be hotter than ``data.T_max`` lets the field be."""
        a, b = self.interval
        flame = sigma < -0.05
        share = float((sigma[flame] <= a + 0.01 * (b - a)).mean()) if flame.any() else 0.0
        out = {"flame_at_prior_bound": share}
        if share > 0.01:
            amb = self.scene.ambient
            what = (f"the hottest {amb.temperature_from_sigma(np.float64(a)):.0f} K the field can hold "
                    f"(data.T_max={amb.T_max:g} K)" if amb.temperature_known else f"the prior's bound sigma = {a:g}")
            out["warnings"] = [f"{100 * share:.1f} % of the flame sits at {what}: it may be hotter; raise "
                               f"{'data.T_max' if amb.temperature_known else 'field.prior'}"]
            log.warning("%s", out["warnings"][0])
        return out

    # --- batches ---
    def rays(self, index: torch.Tensor):
        """Ray origins, directions and observed deflections (sigma units) of scene rays ``index``."""
        views = torch.searchsorted(self.scene.view_start, index, right=True) - 1
        return self.scene.origins[views], self.scene.dirs[index], self.scene.eps[index] / self.scale

    def _measured(self, d: torch.Tensor) -> Optional[torch.Tensor]:
        """Ray directions to project the rendered deflections with, when only their perpendicular part is measured."""
        return d if self.scene.perpendicular_only else None

    def _pools(self, scene: Scene, inside, outside_fraction: float) -> list[tuple[torch.Tensor, Optional[torch.Tensor]]]:
        """Per view: (rays inside its 2-D mask, rays outside it or None), as scene indices; ``inside``: per view,
        the scene indices of the rays inside its 2-D mask (None: every ray)."""
        pools = []
        for v in range(scene.n_views):
            sl = scene.view_slice(v)
            every = torch.arange(sl.start, sl.stop, device=scene.dirs.device)
            if inside is None or len(inside[v]) == 0:  # no mask, or an empty one (warned when it was built)
                pools.append((every, None))
                continue
            outside = every[~torch.isin(every, inside[v])]
            pools.append((inside[v], outside if len(outside) else None))
        return pools

    def draw(self, view: int, n: int) -> torch.Tensor:
        """Scene indices of ``n`` random rays of ``view``: inside its 2-D mask, and ``round(outside_fraction n)``
        of them outside it."""
        inside, outside = self.pools[view]
        n_out = int(round(self.outside_fraction * n)) if outside is not None else 0
        parts = [(inside, n - n_out)] + ([(outside, n_out)] if n_out else [])
        return torch.cat([pool[torch.randint(len(pool), (m,), generator=self.generator, device=self.device)]
                          for pool, m in parts])

    def batch_views(self) -> list[int]:
        """The views of this iteration's batch: the next ``views_per_batch`` views, cycled, so that every view
        is seen equally often (with ``all``, every view in every batch)."""
        n = self.scene.n_views
        k = n if self.views_per_batch == "all" else min(self.views_per_batch, n)
        return [(self.iteration * k + j) % n for j in range(k)]

    def batch(self) -> torch.Tensor:
        """Scene indices of this iteration's ``rays_per_batch`` rays, split evenly over :meth:`batch_views`."""
        views = self.batch_views()
        share, extra = divmod(self.rays_per_batch, len(views))
        counts = [share + (j < extra) for j in range(len(views))]
        return torch.cat([self.draw(v, c) for v, c in zip(views, counts) if c])

    # --- optimisation ---
    def step(self) -> dict:
        """One iteration on the next views (:meth:`batch_views`); returns the loss terms (floats)."""
        t0 = time.perf_counter()
        self.sampler.update(self.field, self.iteration, self.generator)
        o, d, eps_obs = self.rays(self.batch())
        samples = self.sampler(self.scene.box, o, d, self.generator)
        trained = {name: True for name, w in self.weights.items() if w > 0}
        eps = render_deflections(self.field, samples, trained, self.step_mm, dirs=self._measured(d),
                                 stencil=self.stencil)
        terms = deflection_terms(eps, eps_obs)
        loss = weighted_sum(terms, self.weights)
        boundary = self.boundary(self.field, self.generator) if self.boundary is not None else None
        if boundary is not None:
            loss = loss + boundary
        tv = self.tv(self.field, self.generator) if self.tv is not None else None
        if tv is not None:
            loss = loss + tv
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        self.scheduler.step()
        named = {"loss": loss, **{f"loss_{n}": t for n, t in terms.items()}}
        if boundary is not None:
            named["loss_boundary"] = boundary
        if tv is not None:
            named["loss_tv"] = tv
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
        self.samples_seen += len(samples.positions)
        self.rays_seen += samples.n_rays
        self.samples_max = max(self.samples_max, int(stats[-2]))
        self.rays_skipped += int(stats[-1])
        out.update(lr=self.optimizer.param_groups[0]["lr"],
                   samples_per_ray=len(samples.positions) / max(samples.n_rays, 1),
                   rays_skipped=stats[-1] / max(samples.n_rays, 1))
        return out

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
        """Deflections [rad] of rays (R, 3) by each operator, without any parameter graph."""
        out = {n: [] for n in operators}
        chunk = max(1, min(4096, (1 << 18) // self._eval_sampler.samples_per_ray))  # rays per pass: bounded memory
        field = self.estimate
        for i in range(0, len(d), chunk):
            s = self._eval_sampler(self.scene.box, o[i:i + chunk], d[i:i + chunk])
            eps = render_deflections(field, s, {n: False for n in operators}, self.step_mm,
                                     dirs=self._measured(d[i:i + chunk]), stencil=self.stencil)
            for n in operators:
                out[n].append(eps[n].detach() * self.scale)
        return {n: torch.cat(v) if v else d.new_zeros(0, 3) for n, v in out.items()}

    def predicted_deflections(self, index: torch.Tensor, operators=("auto", "discrete")) -> dict:
        """Deflections [rad] of scene rays ``index`` by each operator."""
        o, d, _ = self.rays(index)
        return self.render(o, d, operators)

    def predict(self, origins: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """Deflections [rad] by the operator training fits (:attr:`fitted_operator`)."""
        op = self.fitted_operator
        return self.render(origins, dirs, (op,))[op]

    @property
    def evaluations_per_sample(self) -> int:
        """Field evaluations per sample of a training step: 1 for ``auto`` (plus its double backward), 6 for
        ``discrete`` (4 with ``stencil=across`` on perpendicular-only data), summed over the trained operators."""
        across = self.stencil == "across" and self.scene.perpendicular_only
        cost = {"auto": 1, "discrete": 4 if across else 6}
        return sum(cost[n] for n, w in self.weights.items() if w > 0)

    @property
    def fitted_operator(self) -> str:
        """The gradient operator whose deflections are reported: discrete when it is trained on, else the first
        trained one."""
        trained = [n for n, w in self.weights.items() if w > 0]
        return "discrete" if "discrete" in trained else trained[0]

    def evaluate(self) -> dict:
        """Metrics now: temperature/sigma errors on the grid (when the truth is known), deflection errors."""
        m = {"iteration": self.iteration, "wall_time_s": self.train_seconds, **self.field_errors(self.reconstruction())}
        eps = self.predicted_deflections(self._eval_index)
        obs = self.scene.eps[self._eval_index]
        for n, e in eps.items():
            m[f"deflection_rmse_{n}"] = deflection_rmse(e, obs)
        m["deflection_rmse"] = m[f"deflection_rmse_{self.fitted_operator}"]
        m.update(self.heldout_errors())
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
                "samples_max": self.samples_max, "rays_skipped": self.rays_skipped, "converged": self.converged}

    def _load_field(self, st: dict, weights: Optional[dict] = None) -> None:
        try:
            self.field.load_state_dict(st["field"] if weights is None else weights)
        except RuntimeError as e:
            raise ValueError("the checkpoint was made with another field configuration (encoder/field settings "
                             f"differ): {str(e).splitlines()[0]}") from None
        self.sampler.load_state_dict(st.get("sampler", {}))

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
        try:
            self.optimizer.load_state_dict(st["optimizer"])
        except ValueError as e:
            raise ValueError("the checkpoint's optimiser state does not fit this solver (made by a nerif before "
                             f"train.table_decay, or with another encoder): {str(e).splitlines()[0]}") from None
        self.scheduler.load_state_dict(st["scheduler"])
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
                "field_evaluations_per_sample": self.evaluations_per_sample,
                "samples_per_ray_mean": self.samples_seen / max(self.rays_seen, 1), "samples_per_ray_max": self.samples_max,
                "rays_skipped_fraction": self.rays_skipped / max(self.rays_seen, 1)}
