"""Validation of displacement vectors as PIV validates its own: the normalised median test (Westerweel and Scarano
2005, Exp. Fluids 39:1096). A vector whose difference from the median of its 8 neighbours exceeds ``threshold``
times the neighbours' median difference from that median (plus ``eps_px``, the flow's noise floor) is rejected."""
from __future__ import annotations

import warnings

import numpy as np


def median_test(u: np.ndarray, valid: np.ndarray, threshold: float = 2.0, eps_px: float = 0.1) -> np.ndarray:
    """(h, w) bool: the vectors of ``u`` (h, w, 2) the normalised median test rejects, among the ``valid`` (h, w)
    ones (invalid neighbours do not vote; a vector with fewer than 3 valid neighbours is kept)."""
    h, w = valid.shape
    pad = np.pad(np.where(valid[..., None], u, np.nan), ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
    neighbours = np.stack([pad[1 + dr:1 + dr + h, 1 + dc:1 + dc + w] for dr in (-1, 0, 1) for dc in (-1, 0, 1)
                           if dr or dc], -2)  # (h, w, 8, 2)
    count = np.isfinite(neighbours[..., 0]).sum(-1)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a pixel with no valid neighbour: an all-NaN slice
        med = np.nanmedian(neighbours, -2)  # (h, w, 2)
        spread = np.nanmedian(np.abs(neighbours - med[..., None, :]), -2)
        residual = np.abs(u - med) / (spread + eps_px)
        bad = np.nanmax(residual, -1) > threshold
    return valid & (count >= 3) & np.nan_to_num(bad, nan=False).astype(bool)

