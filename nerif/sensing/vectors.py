"""Validation of displacement vectors as PIV validates its own: the normalised median test (Westerweel and Scarano
2005, Exp. Fluids 39:1096). A vector whose difference from the median of its 8 neighbours exceeds ``threshold``
times the neighbours' median difference from that median (plus ``eps_px``, the flow's noise floor) is rejected,
unless several vectors around it share its value: a coherent sharp structure (a shock, a flame sheet, an interface)
is data, an outlier stands alone. The floor is at least twice the view's own measured noise (:func:`vector_noise`):
a camera noisier than the floor set would otherwise lose vectors wherever nothing flows."""
from __future__ import annotations

import warnings

import numpy as np

COHERENT = 4  # vectors within a 7 x 7 neighbourhood that share a vector's value make it a structure, not an outlier


def _neighbours(u: np.ndarray, valid: np.ndarray, reach: int) -> np.ndarray:
    """(h, w, n, 2) the valid vectors around each one within ``reach`` (the vector itself left out; NaN where none)."""
    h, w = valid.shape
    pad = np.pad(np.where(valid[..., None], u, np.nan), ((reach, reach), (reach, reach), (0, 0)),
                 constant_values=np.nan)
    return np.stack([pad[reach + dr:reach + dr + h, reach + dc:reach + dc + w]
                     for dr in range(-reach, reach + 1) for dc in range(-reach, reach + 1) if dr or dc], -2)


def vector_noise(u: np.ndarray, valid: np.ndarray, near: np.ndarray | None = None) -> float:
    """The vectors' noise [their unit]: the robust standard deviation (1.4826 times the median absolute value) of
    each valid vector's difference from the median of its 8 neighbours (``near``: :func:`_neighbours` within 1,
    where the caller has them), both components pooled; 0 with too few."""
    near = _neighbours(u, valid, 1) if near is None else near
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        d = (u - np.nanmedian(near, -2))[valid & (np.isfinite(near[..., 0]).sum(-1) >= 3)]
    d = d[np.isfinite(d)]
    return float(1.4826 * np.median(np.abs(d))) if d.size >= 20 else 0.0


def median_test(u: np.ndarray, valid: np.ndarray, threshold: float = 2.0, eps_px: float = 0.1) -> np.ndarray:
    """(h, w) bool: the vectors of ``u`` (h, w, 2) the normalised median test rejects, among the ``valid`` (h, w)
    ones (invalid neighbours do not vote; a vector with fewer than 3 valid neighbours is kept), with the floor
    ``max(eps_px, 2 vector_noise)``; a vector that at least :data:`COHERENT` others of its 7 x 7 neighbourhood match
    (each component within the test's bound) is kept."""
    near = _neighbours(u, valid, 1)  # (h, w, 8, 2)
    eps = max(float(eps_px), 2.0 * vector_noise(u, valid, near))
    count = np.isfinite(near[..., 0]).sum(-1)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a pixel with no valid neighbour: an all-NaN slice
        med = np.nanmedian(near, -2)  # (h, w, 2)
        bound = np.nanmedian(np.abs(near - med[..., None, :]), -2) + eps  # (h, w, 2)
        bad = np.nan_to_num(np.nanmax(np.abs(u - med) / bound, -1) > threshold, nan=False).astype(bool)
        bad &= valid & (count >= 3)
        if bad.any():  # a coherent structure: enough of the vectors around share the value
            wide = _neighbours(u, valid, 3)[bad]  # (B, 48, 2)
            alike = (np.abs(wide - u[bad][:, None, :]) <= threshold * bound[bad][:, None, :]).all(-1).sum(-1)
            bad[bad] = alike < COHERENT
    return bad
