"""How far to trust each voxel (``uncertainty=``): a per-voxel standard deviation of sigma with a reconstruction.

``none`` adds nothing. ``ensemble`` (:class:`ViewEnsemble`) trains members that each leave some training views out
(the limited-view ambiguity: what one view fewer leaves free), spreads their answers per voxel, and scales the
spread so that it explains what the field itself gets wrong on the views it never trained on (the held-out
views): the data's error level is read from the data, not
assumed; without held-out views the spread is returned as it is, with a warning. Both are built from the
``uncertainty`` config group and called with a trained solver.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import torch

from nerif.masks.backprojection import views_seeing
from nerif.registry import Registry
from nerif.solvers.trained import why_not
from nerif.units import SIGMA, declare

log = logging.getLogger(__name__)

declare(uncertainty_member_iterations="iterations", uncertainty_members="fields", uncertainty_scale="1 (factor)",
        uncertainty_spread_median=SIGMA, text=("uncertainty", "uncertainty_scale_from"))

UNCERTAINTY = Registry("uncertainty", package="nerif.solvers")


@dataclass(frozen=True)
class Estimate:
    """What an uncertainty method found about a trained result, handed to :func:`nerif.results.results` beside it.

    Attributes:
        volumes: name -> (nx, ny, nz) on the probe grid: ``sigma_std`` [sigma], ``views_seeing`` [views]; empty
            where none was estimated (``uncertainty=none``, or a signal ended it).
        report: ``metrics.json``'s figures of the method (each unit declared in its module).
    """

    volumes: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)


@UNCERTAINTY.register("none")
class NoUncertainty:
    """No uncertainty: the run as it was."""

    def check(self, solver) -> None:
        pass

    def __call__(self, solver, stop=None) -> Estimate:
        return Estimate()


def left_out_views(n_views: int, members: int, leave_out: int) -> list[list[int]]:
    """Per member, the training views it leaves out: ``leave_out`` views, spread evenly over the arc and shifted
    from member to member, so that together the members leave out views all round."""
    out = []
    for k in range(members):
        first = (k * n_views) // members
        out.append(sorted({(first + j * n_views // max(leave_out, 1)) % n_views for j in range(leave_out)}))
    return out


@UNCERTAINTY.register("ensemble")
class ViewEnsemble:
    """The spread of ``members`` fields, each the trained one trained on for ``fraction`` of the run's iterations
    without ``leave_out`` of the training views (different views for each member, :func:`left_out_views`), with its
    own ray draws; scaled by a factor read from the held-out views, which no field trained on (:func:`calibration`).

    Args:
        members: fields in the ensemble (at least 2).
        fraction: each member's iterations as a share of those the run made (its cost: ``members x fraction`` of a
            run's training).
        leave_out: training views each member leaves out (at least 1, fewer than the training views less 1).
        lr_factor: each member's learning rate at its start, a share of the run's peak.
        perturb: each member starts from the trained field perturbed by this share of its own size (the encoder's
            tables: :meth:`nerif.solvers.neural.NeuralSolver.member`), so that what no ray pins down spreads.
        seed: the members' random draws (member k: ``seed + k``).
    Returns from a call: ``volumes`` (``sigma_std``: (nx, ny, nz) the standard deviation of sigma, at least that of
    a uniform spread over the field's prior interval where no training ray reaches a voxel (the data say nothing
    there; a 3-D mask's ambient outside the views is an assumption); ``views_seeing``: the training views whose rays
    reach each voxel) and ``report`` (the calibration factor, what it was read from,
    the members' time).
    """

    def __init__(self, members: int = 4, fraction: float = 0.06, leave_out: int = 1, lr_factor: float = 0.3,
                 perturb: float = 0.5, seed: int = 1):
        if isinstance(members, bool) or not isinstance(members, int) or members < 2:
            raise ValueError(f"uncertainty.members={members!r}: a whole number of at least 2 fields")
        if not 0.0 < float(fraction) <= 1.0:
            raise ValueError(f"uncertainty.fraction={fraction}: each member's share of the run's iterations, "
                             "within (0, 1]")
        if isinstance(leave_out, bool) or not isinstance(leave_out, int) or leave_out < 1:
            raise ValueError(f"uncertainty.leave_out={leave_out!r}: a whole number of views, at least 1")
        if not 0.0 < float(lr_factor) <= 1.0:
            raise ValueError(f"uncertainty.lr_factor={lr_factor}: a share of the run's peak learning rate, "
                             "within (0, 1]")
        self.members, self.fraction, self.leave_out = members, float(fraction), leave_out
        if not 0.0 <= float(perturb) <= 10.0:
            raise ValueError(f"uncertainty.perturb={perturb}: a share of the field's own size, within [0, 10]")
        self.lr_factor, self.perturb, self.seed = float(lr_factor), float(perturb), int(seed)

    def check(self, solver) -> None:
        """One sentence before any training where the solver cannot train members or the training views cannot
        spare ``leave_out``."""
        why = why_not(solver, field=True)
        if why:
            raise ValueError(f"uncertainty=ensemble needs a trained field to start its members from: {why}; use "
                             "uncertainty=none, or solver=nerif")
        why = why_not(solver, leave_out=self.leave_out)
        if why:
            raise ValueError(f"uncertainty.leave_out={self.leave_out}: {why}; leave out fewer")

    def __call__(self, solver, stop=None) -> Estimate:
        """The uncertainty of ``solver``'s trained result (a :class:`~nerif.solvers.trained.TrainedField`, left as it
        was: each member is its clone); ``stop()`` true (a signal) ends it between steps and
        returns nothing."""
        scene = solver.scene
        t0 = time.perf_counter()
        iterations = max(1, int(round(self.fraction * solver.iteration)))  # of those run (a run may stop early)
        held = not why_not(solver, heldout=True)  # a view no field trained on, to calibrate by
        left = left_out_views(scene.n_views, self.members, self.leave_out)
        fields, held_pred = [], []
        for k, out in enumerate(left):
            member = solver.clone([v for v in range(scene.n_views) if v not in out], self.seed + k,
                                  iterations=iterations, lr_factor=self.lr_factor, perturb=self.perturb)
            if not member.train(stop):
                return Estimate()
            fields.append(member.reconstruction())
            if held:
                held_pred.append(heldout_fit(member))
            log.info("uncertainty: member %d of %d (without %s) trained for %d iterations", k + 1, self.members,
                     ", ".join(scene.cameras[v].name for v in out), iterations)
        report = {"uncertainty": "ensemble", "uncertainty_members": self.members,
                  "uncertainty_member_iterations": iterations}
        return calibrated_spread(solver, fields, held_pred, report, t0)


@UNCERTAINTY.register("auto")
class AutomaticUncertainty(ViewEnsemble):
    """The default: a :class:`ViewEnsemble` (same settings) where a run can calibrate one, the solver training
    members, the data holding a view out and the training views sparing ``leave_out``; else no uncertainty, said
    in the log (never a refusal: a run without a held-out view goes on as it was). Measured on the shared captures
    at 1.1-1.3x a run's time (issue 59: benchmarks/RESULTS.md)."""

    def without(self, solver) -> str:
        """Why this run cannot calibrate an ensemble, in words; empty where it can (:func:`why_not`)."""
        return why_not(solver, field=True, heldout=True, leave_out=self.leave_out)

    def check(self, solver) -> None:
        pass

    def __call__(self, solver, stop=None) -> Estimate:
        why = self.without(solver)
        if why:
            log.info("uncertainty=auto: %s: no uncertainty estimated", why)
            return Estimate()
        return super().__call__(solver, stop)


def calibrated_spread(solver, fields: list[np.ndarray], held_pred: list[torch.Tensor], report: dict,
                      t0: float) -> Estimate:
    """What an uncertainty method returns from the fields it drew about ``solver``'s result: their spread per voxel
    (``fields``: K (nx, ny, nz) sigma), scaled by :func:`calibration` so that it explains the field's error on the
    held-out views (``held_pred``: K (R, 3) their predictions there; empty without held-out views: the spread as it
    is, with a warning), at least a uniform spread over the field's prior interval where no training ray reaches a
    voxel; ``volumes`` (``sigma_std``, ``views_seeing``) and ``report`` (``report`` with the scale, what it was
    read from, the time since ``t0`` and the spread's median)."""
    scene = solver.scene
    spread = np.std(np.stack(fields), axis=0, ddof=1)
    if held_pred:
        factor, source = calibration(heldout_fit(solver), torch.stack(held_pred), scene.heldout.observed), \
            "held-out views"
    else:  # the fields started from one that saw every training view: their residuals there say nothing
        factor, source = 1.0, "none (no held-out view)"
        log.warning("uncertainty: no held-out view to calibrate the spread by; sigma_std is the spread as it is, "
                    "likely too narrow (hold a view out: data.heldout)")
    log.info("uncertainty: %d fields (%s), spread scaled by %.3g (read from %s) in %.1f s", len(fields),
             report["uncertainty"], factor, source, time.perf_counter() - t0)
    seeing = views_seeing(scene.box, scene.cameras,
                          [scene.view_image(v, np.ones(int(scene.view_counts()[v]))) > 0
                           for v in range(scene.n_views)])
    std = factor * spread
    a, b = solver.interval
    std[seeing == 0] = np.maximum(std[seeing == 0], (b - a) / 12 ** 0.5)  # no ray: only the prior's bounds
    return Estimate({"sigma_std": std, "views_seeing": seeing.astype(np.float64)},
                    {**report, "uncertainty_scale": float(factor), "uncertainty_scale_from": source,
                     "uncertainty_time_s": time.perf_counter() - t0,
                     "uncertainty_spread_median": float(np.median(spread))})


def heldout_fit(solver) -> torch.Tensor:
    """(R, 3) the solver's predicted deflections of every held-out ray, in the unit of ``observed`` (sigma)."""
    h = solver.scene.heldout
    return solver.predict(h.origins[h.ray_views()], h.dirs)


def calibration(fit: torch.Tensor, members: torch.Tensor, observed: torch.Tensor,
                quiet_share: float = 0.05) -> float:
    """The factor that makes the members' spread explain the field's error on views it did not train on.

    Args:
        fit: (R, 3) the field's predicted deflections of those rays (sigma units).
        members: (K, R, 3) each member's.
        observed: (R, 3) what those views measured.
        quiet_share: rays whose predicted deflection is below this share of the largest count as seeing no flame:
            their residual is the measurement's noise, taken off the others' before the comparison.
    Returns ``sqrt((mean |r|^2 - noise^2) / mean s^2)`` over the rays that see the flame, ``r`` the field's residual
    and ``s^2`` the members' variance (at least 0.1).
    """
    r2 = (fit - observed).double().pow(2).sum(-1)
    s2 = members.double().var(0, unbiased=True).sum(-1)
    size = fit.double().norm(dim=-1)
    flame = size > quiet_share * float(size.max()) if len(size) else size.bool()
    noise2 = float(r2[~flame].mean()) if bool((~flame).sum() > 10) else 0.0
    if not bool(flame.any()) or float(s2[flame].mean()) <= 0.0:
        return 1.0
    return float(max(0.01, (float(r2[flame].mean()) - noise2) / float(s2[flame].mean())) ** 0.5)
