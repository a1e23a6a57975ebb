"""Camera vibration between the two exposures: each view's rigid image motion, a translation of the whole
background, adds to every displacement the flow measures. It is read where no flame deflects (outside the probe
box's image, where that leaves enough pixels, else wherever the displacements are those of the bulk) and taken
off. Real image pairs show 0.03-0.2 px of it, as much as a flame's displacements."""
from __future__ import annotations

import numpy as np

MIN_QUIET = 200  # pixels of the ray grid needed to read the shift from


def _robust_centre(u: np.ndarray) -> np.ndarray:
    """The (2,) median of (N, 2) displacements, refined over those within 3 robust deviations of it (the bulk)."""
    centre = np.median(u, 0)
    for _ in range(3):
        r = np.linalg.norm(u - centre, axis=-1)
        spread = 1.4826 * float(np.median(r)) + 1e-6
        bulk = u[r < 3.0 * spread]
        if len(bulk) < MIN_QUIET // 4:
            break
        centre = np.median(bulk, 0)
    return centre


def rigid_shift(u: np.ndarray, valid: np.ndarray, quiet: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """A view's rigid shift [the unit of ``u``] (2,) (column, row) and where it was read.

    Args:
        u: (h, w, 2) displacements; valid: (h, w) bool, the usable ones.
        quiet: (h, w) bool, the pixels that see no flame (outside the probe box's image), or None.
    Returns: the shift, and ``"outside the probe box"`` or ``"the bulk of the view"``.
    """
    if quiet is not None and int((quiet & valid).sum()) >= MIN_QUIET:
        return _robust_centre(u[quiet & valid]), "outside the probe box"
    if int(valid.sum()) == 0:
        return np.zeros(2), "nowhere (no valid pixel)"
    return _robust_centre(u[valid]), "the bulk of the view"
