"""What the realistic chain (:func:`nerif.sensing.realistic.realistic`) saw and measured in each view, kept for the
scene, its figures and its scores: one record, its fields named, cached as plain arrays."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Optional

import numpy as np

from nerif.units import SHARE, declare

declare(occluded_true=SHARE)


@dataclass(frozen=True)
class SensingRecord:
    """The realistic chain's record of V views.

    Attributes:
        displacement_px: (V, h, w, 2) float32, the displacements measured on the ray grid [px of the full sensor],
            NaN where the flow gave no estimate.
        valid: (V, h, w) bool, the rays the measurement stage kept.
        left_out: (V, h, w) uint8, why it left the others out (an index into
            :data:`nerif.sensing.measurement.CAUSES`; 0: kept).
        reference, distorted: (V, H, W) uint8, the two exposures as a camera saves them.
        u_true, u_est: (V, h, w, 2) float32, the true and the measured displacements on the ray grid [px of the
            images' grid].
        circle_of_confusion_px: (V,) the background's blur in each view [px of the images' grid].
        displacement_rmse_px: the measured displacements' RMS error over the training rays [px of the images' grid].
        shake_true_px: (V, 2) the vibration put between the exposures [px of the full sensor].
        occluded_true: (V,) the share of each view's ray grid that sees the burner, or None without one.
        found: what the measurement stage found, name -> (V, ...) per view
            (:attr:`nerif.sensing.measurement.ViewMeasurement.found`).
    """
    displacement_px: np.ndarray
    valid: np.ndarray
    left_out: np.ndarray
    reference: np.ndarray
    distorted: np.ndarray
    u_true: np.ndarray
    u_est: np.ndarray
    circle_of_confusion_px: np.ndarray
    displacement_rmse_px: float
    shake_true_px: np.ndarray
    occluded_true: Optional[np.ndarray] = None
    found: dict = field(default_factory=dict)

    def arrays(self) -> dict:
        """Plain arrays for a cache (``found/NAME`` for each finding); :meth:`from_arrays` reads them back."""
        out = {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)
               if f.name != "found" and getattr(self, f.name) is not None}
        return {**out, **{f"found/{k}": np.asarray(v) for k, v in self.found.items()}}

    @classmethod
    def from_arrays(cls, arrays: dict) -> "SensingRecord":
        found = {k[len("found/"):]: v for k, v in arrays.items() if k.startswith("found/")}
        names = {f.name for f in fields(cls)} - {"found"}
        kw = {k: v for k, v in arrays.items() if k in names}
        return cls(**{**kw, "displacement_rmse_px": float(kw["displacement_rmse_px"])}, found=found)

    @classmethod
    def of_views(cls, views: list, displacement_rmse_px: float) -> "SensingRecord":
        """The record of ``views``, one dict per view with a value for each field (``found``: name -> value)."""
        stacked = {f.name: np.stack([v[f.name] for v in views]) for f in fields(cls)
                   if f.name not in ("found", "displacement_rmse_px") and views[0].get(f.name) is not None}
        found = {k: np.stack([np.asarray(v["found"][k], dtype=np.float64) for v in views]) for k in views[0]["found"]}
        return cls(**stacked, displacement_rmse_px=float(displacement_rmse_px), found=found)

    def report(self) -> dict:
        """``metrics.json``'s figures of the chain: the flow's error [px], the widest blur and each view's [px], and
        what the chain put in to score what the stage found (each view's shake [px of the full sensor], the share of
        its rays the burner hides)."""
        coc = np.atleast_1d(self.circle_of_confusion_px)
        out = {"displacement_rmse_px": float(self.displacement_rmse_px),
               "circle_of_confusion_px": float(coc.max()),
               "circle_of_confusion_px_per_view": [float(c) for c in coc],
               "shake_true_px": [[float(x) for x in s] for s in self.shake_true_px]}
        if self.occluded_true is not None:
            out["occluded_true"] = [float(x) for x in self.occluded_true]
        return out
