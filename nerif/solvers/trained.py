"""The contract of a trained field: all that the uncertainty methods (:mod:`nerif.solvers.uncertainty`,
:mod:`nerif.solvers.laplace`) use of a solver whose result is a field trained on rays, and where a run can carry a
calibrated uncertainty (:func:`why_not`, the one place the conditions of ``uncertainty=auto`` are written). A second
field representation fits every uncertainty method by implementing :class:`TrainedField`; nothing else of the
solver is read.
"""
from __future__ import annotations

from typing import Callable, Optional, Protocol, runtime_checkable

import numpy as np
import torch


@runtime_checkable
class TrainedField(Protocol):
    """A solver whose result is a field trained on the rays of its ``scene``.

    Attributes:
        scene: the :class:`~nerif.data.Scene` it was trained on (its training views, ``heldout`` the views never
            trained on), read only.
        generator: the random stream of its ray draws (a clone's own: ``clone(..., seed)``).
        interval: (a, b) the bounds of its sigma (its prior).
        iteration: the steps it has taken.
    """

    scene: object
    generator: torch.Generator
    interval: tuple
    iteration: int

    def clone(self, views: list[int], seed: int, *, iterations: int = 0, lr_factor: float = 1.0,
              perturb: float = 0.0) -> "TrainedField":
        """A new field from this one's trained state (which is left as it is): its parameters perturbed by
        ``perturb`` (a share of each tensor's own size), to be trained (:meth:`train`) for ``iterations`` more
        steps on the training ``views`` only, from ``lr_factor`` of its peak learning rate, its own random draws
        from ``seed``. The scene is shared, read only."""

    def parameters(self) -> list[torch.Tensor]:
        """The field's trained tensors (what a step changes)."""

    def batch_loss(self, update_occupancy: bool = True) -> tuple[dict, object]:
        """The next batch's loss terms (``loss``: their weighted sum) with its graph to :meth:`parameters`, and the
        samples; ``update_occupancy`` False: no skipping structure is changed."""

    def train(self, stop: Optional[Callable[[], bool]] = None) -> bool:
        """Steps to its iterations (no evaluation, no checkpoint); ``stop()`` true ends it. Whether it finished."""

    def reconstruction(self) -> np.ndarray:
        """(nx, ny, nz) sigma on the probe grid."""

    def predict(self, origins: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """(R, 3) deflections of rays (R, 3) through the field, in the unit of the scene's ``observed``."""


def why_not(solver, *, field: bool = False, heldout: bool = False, leave_out: int = 0) -> str:
    """The first condition ``solver`` does not meet, in words (empty where it meets them): ``field``, a trained
    field (:class:`TrainedField`); ``heldout``, a view the data hold out; ``leave_out`` training views each member
    of an ensemble leaves out while keeping at least 2."""
    if field and not isinstance(solver, TrainedField):
        return f"solver={solver.name} has no trained field"
    scene = solver.scene
    if heldout and (scene.heldout is None or len(scene.heldout.dirs) == 0):
        return "the data hold no view out to calibrate the spread by (data.heldout)"
    if leave_out > scene.n_views - 2:
        return f"{scene.n_views} training views cannot spare {leave_out} a member and keep 2"
    return ""
