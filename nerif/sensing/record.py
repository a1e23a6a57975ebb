"""What the realistic chain (:func:`nerif.sensing.realistic.realistic`) made of V views, in two records, each cached
as plain arrays: what a capture's views would hold too (:class:`MeasuredViews`: the two exposures as a camera saves
them and what the measurement stage found in them), which becomes the scene's views, and what only the chain knows
(:class:`SensingRecord`: the truth it put in, and the measurement's error against it), kept for figures and scores."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Optional

import numpy as np

from nerif.sensing.findings import Findings
from nerif.units import SHARE, declare

declare(occluded_true=SHARE)


def _arrays(record) -> dict:
    """A record's fields that are set, as plain arrays (``found``: ``found/NAME`` for each finding)."""
    out = {f.name: np.asarray(getattr(record, f.name)) for f in fields(record)
           if f.name != "found" and getattr(record, f.name) is not None}
    return {**out, **{f"found/{k}": np.asarray(v) for k, v in getattr(record, "found", {}).items()}}


def _stacked_finding(values: list) -> np.ndarray:
    """(V, ...) float64 of one finding over the views, NaN where a view has none (None: the stage could not make
    it), shaped as the views that have one."""
    shape = next((np.shape(x) for x in values if x is not None), ())
    return np.stack([np.full(shape, np.nan) if x is None else np.asarray(x, dtype=np.float64) for x in values])


def _missing_as_none(value):
    """A view's finding as :func:`_stacked_finding` stored it: None where it is NaN throughout (no finding)."""
    return None if np.all(np.isnan(np.asarray(value, dtype=np.float64))) else value


def _fields(cls, arrays: dict) -> dict:
    """The keyword arguments of ``cls`` in ``arrays`` (as :func:`_arrays` wrote them)."""
    names = {f.name for f in fields(cls)} - {"found"}
    return {k: v for k, v in arrays.items() if k in names}


@dataclass(frozen=True)
class MeasuredViews:
    """What the realistic chain recorded and measured in V views, as a capture's views hold it.

    Attributes:
        reference, distorted: (V, H, W) uint8, the two exposures as a camera saves them.
        displacement_px: (V, h, w, 2) float32, the displacements measured on the ray grid [px of the full sensor],
            NaN where left out.
        valid: (V, h, w) bool, the rays the measurement stage kept.
        left_out: (V, h, w) uint8, why it left the others out (an index into
            :data:`nerif.sensing.measurement.CAUSES`; 0: kept).
        found: what the measurement stage found, a :class:`Findings` field -> (V, ...) per view.
    """

    reference: np.ndarray
    distorted: np.ndarray
    displacement_px: np.ndarray
    valid: np.ndarray
    left_out: np.ndarray
    found: dict = field(default_factory=dict)

    def arrays(self) -> dict:
        """Plain arrays for a cache; :meth:`from_arrays` reads them back."""
        return _arrays(self)

    @classmethod
    def from_arrays(cls, arrays: dict) -> "MeasuredViews":
        found = {k[len("found/"):]: v for k, v in arrays.items() if k.startswith("found/")}
        return cls(**_fields(cls, arrays), found=found)

    def findings(self) -> list[Findings]:
        """Each view's :class:`Findings`; a finding the stage could not make in a view (stored as NaN) is None
        there, as the stage left it."""
        per_view = {k: v.tolist() for k, v in self.found.items()}
        return [Findings.read({k: _missing_as_none(x[v]) for k, x in per_view.items()}) for v in range(len(self.valid))]


@dataclass(frozen=True)
class SensingRecord:
    """What only the realistic chain knows of its V views: the truth it put in, and how well the stage measured it.

    Attributes:
        u_true: (V, h, w, 2) float32, the true displacements on the ray grid [px of the images' grid].
        circle_of_confusion_px: (V,) the background's blur in each view [px of the images' grid].
        displacement_rmse_px: the measured displacements' RMS error over the training rays [px of the images' grid].
        shake_true_px: (V, 2) the vibration put between the exposures [px of the full sensor].
        occluded_true: (V,) the share of each view's ray grid that sees the burner, or None without one.
    """

    u_true: np.ndarray
    circle_of_confusion_px: np.ndarray
    displacement_rmse_px: float
    shake_true_px: np.ndarray
    occluded_true: Optional[np.ndarray] = None

    def arrays(self) -> dict:
        """Plain arrays for a cache; :meth:`from_arrays` reads them back."""
        return _arrays(self)

    @classmethod
    def from_arrays(cls, arrays: dict) -> "SensingRecord":
        kw = _fields(cls, arrays)
        return cls(**{**kw, "displacement_rmse_px": float(kw["displacement_rmse_px"])})

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


def chain_records(views: list[dict], displacement_rmse_px: float) -> tuple[MeasuredViews, SensingRecord]:
    """The two records of ``views``, one dict per view with a value for each field of either (``found``: a
    :class:`Findings` field -> value)."""
    def stacked(cls) -> dict:
        return {f.name: np.stack([v[f.name] for v in views]) for f in fields(cls)
                if f.name not in ("found", "displacement_rmse_px") and views[0].get(f.name) is not None}

    found = {k: _stacked_finding([v["found"][k] for v in views]) for k in views[0]["found"]}
    return (MeasuredViews(**stacked(MeasuredViews), found=found),
            SensingRecord(**stacked(SensingRecord), displacement_rmse_px=float(displacement_rmse_px)))
