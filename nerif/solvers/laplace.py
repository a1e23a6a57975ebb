"""``uncertainty=laplace``: a per-voxel standard deviation of sigma from a Laplace approximation around the trained
field, at a small share of the ensemble's cost.

The loss near its minimum is read as a Gaussian posterior over the field's parameters whose precision is the loss's
curvature, estimated on its diagonal by the mean squared gradient of random batches (the empirical Fisher) plus a
damping that stands for a prior where the rays pin a parameter down little. Fields drawn from it (each tensor's draw
scaled to a share of its own size, shaped by the posterior's variances) spread per voxel; the spread is scaled, as
the ensemble's is, so that it explains the field's error on the held-out views (:func:`calibrated_spread`). No
field is trained: its cost is ``batches`` gradients and ``samples`` evaluations of the field on the grid.
"""
from __future__ import annotations

import logging
import time

import torch

from nerif.solvers.trained import why_not
from nerif.solvers.uncertainty import UNCERTAINTY, Estimate, calibrated_spread, heldout_fit
from nerif.units import declare

log = logging.getLogger(__name__)

declare(uncertainty_samples="fields", uncertainty_curvature_batches="batches")


@UNCERTAINTY.register("laplace")
class LaplaceApproximation:
    """The spread of ``samples`` fields drawn from a diagonal Laplace approximation of the posterior around the
    trained one, calibrated on the held-out views.

    Args:
        batches: random ray batches whose squared loss gradients estimate the curvature (the training's own batch
            size, the observed deflections of every training view).
        samples: fields drawn.
        damping: the prior's precision, a share of each tensor's mean curvature (where the rays say little, the
            draw is as wide as this allows).
        step: each tensor's draw has an RMS of this share of the tensor's own (small: the spread is then linear in
            it, and the calibration sets its scale).
        seed: the batches' and the draws' random stream.
    Returns from a call what :func:`~nerif.solvers.uncertainty.calibrated_spread` returns (``sigma_std``,
    ``views_seeing``; the scale and the method's cost).
    """

    def __init__(self, batches: int = 64, samples: int = 8, damping: float = 0.01, step: float = 0.05, seed: int = 1):
        for name, value, least in (("batches", batches, 1), ("samples", samples, 2)):
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"uncertainty.{name}={value!r}: a whole number of at least {least}")
        if not 0.0 < float(damping) <= 10.0:
            raise ValueError(f"uncertainty.damping={damping}: a share of the mean curvature, within (0, 10]")
        if not 0.0 < float(step) <= 1.0:
            raise ValueError(f"uncertainty.step={step}: a share of each tensor's size, within (0, 1]")
        self.batches, self.samples, self.damping, self.step = batches, samples, float(damping), float(step)
        self.seed = int(seed)

    def check(self, solver) -> None:
        """One sentence before any training where the solver has no trained field to draw from."""
        why = why_not(solver, field=True)
        if why:
            raise ValueError(f"uncertainty=laplace needs a trained field to draw from: {why}; use uncertainty=none, "
                             "or solver=nerif")

    def __call__(self, solver, stop=None) -> Estimate:
        """The uncertainty of ``solver``'s trained result (a :class:`~nerif.solvers.trained.TrainedField`), which is
        left as it was (the draws are its clone's); ``stop()`` true (a signal) ends it and returns
        nothing."""
        t0 = time.perf_counter()
        scene = solver.scene
        draw = solver.clone(list(range(scene.n_views)), self.seed)  # the trained field; never trained on
        params = draw.parameters()
        curvature = [torch.zeros_like(p) for p in params]
        for _ in range(self.batches):
            if stop is not None and stop():
                return Estimate()
            # the iteration does not advance: an occupancy update due at it would run on every batch
            grads = torch.autograd.grad(draw.batch_loss(update_occupancy=False)[0]["loss"], params, allow_unused=True)
            for c, g in zip(curvature, grads):
                if g is not None:
                    c.add_(g.detach().pow(2), alpha=1.0 / self.batches)
        widths = []  # per tensor: the draw's standard deviation per entry
        for p, c in zip(params, curvature):
            variance = 1.0 / (c + self.damping * c.mean().clamp(min=torch.finfo(c.dtype).tiny))
            size = p.detach().pow(2).mean().sqrt()
            widths.append(variance.sqrt() * (self.step * size / variance.mean().sqrt()))
        trained = [p.detach().clone() for p in params]
        fields, held_pred = [], []
        held = not why_not(solver, heldout=True)  # a view no field trained on, to calibrate by
        for _ in range(self.samples):
            if stop is not None and stop():
                return Estimate()
            with torch.no_grad():
                for p, mean, width in zip(params, trained, widths):
                    p.copy_(mean + width * torch.randn(p.shape, generator=draw.generator, device=p.device,
                                                       dtype=p.dtype))
            fields.append(draw.reconstruction())
            if held:
                held_pred.append(heldout_fit(draw))
        log.info("uncertainty: %d fields drawn from the Laplace approximation (%d batches of curvature)",
                 self.samples, self.batches)
        report = {"uncertainty": "laplace", "uncertainty_samples": self.samples,
                  "uncertainty_curvature_batches": self.batches}
        return calibrated_spread(solver, fields, held_pred, report, t0)
