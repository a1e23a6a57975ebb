"""Camera vibration between the two exposures: each view's rigid image motion, a translation of the whole
background, adds to every displacement the flow measures. It is read where no flame deflects (outside the probe
box's image, where that leaves enough pixels, else wherever the displacements are those of the bulk) and taken
off. Real image pairs show 0.03-0.2 px of it, as much as a flame's displacements.

The flow reads it as it reads every displacement, with its own gain (Farneback: 1.1-1.2x on sub-pixel shifts): its
reading is what its vectors hold (:func:`rigid_shift`), not what the images hold, which they say themselves
(:func:`photometric_shift`, through the band-limited picture the image term reads them by).
"""
from __future__ import annotations

import cv2
import numpy as np
import torch

MIN_QUIET = 200  # pixels of the ray grid needed to read the shift from
POINTS = 2**14  # image pixels :func:`photometric_shift` reads, at most


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


def photometric_shift(distorted: np.ndarray, reference: np.ndarray, where: np.ndarray, start: np.ndarray,
                      width_px: float, iterations: int = 8) -> np.ndarray:
    """The rigid shift ``s`` [image px] (2,) (column, row) with ``distorted(x) = reference(x + s)`` on the pixels
    ``where`` (H, W) bool (outside the probe box's image): Gauss-Newton from ``start`` (the flow's reading) on the
    two images (H, W) read through their band-limited picture (:mod:`nerif.sensing.interpolation`), each less its
    blur over 4 texture widths ``width_px`` and divided by its local RMS there (the flame's light, a drift or a gain
    ramp between the exposures moves nothing). At most :data:`POINTS` pixels, drawn once, on the 16 tiles of 512 px
    that hold the most of ``where`` where the images are larger (:func:`nerif.sensing.noise.residual_noise`'s).
    Measured on a Poisson-disk pattern shifted exactly (the pixels integrating it): 0.98-1.00x the true shift,
    where the flow reads 1.10-1.15x; ``start`` where fewer than :data:`MIN_QUIET` pixels are given."""
    from nerif.sensing.interpolation import interpolation
    from nerif.sensing.noise import BLUR_WIDTHS, grown_tiles

    blur_px = BLUR_WIDTHS * float(width_px)
    margin = int(np.ceil(3 * blur_px)) + 4
    H, W = reference.shape
    inner = np.zeros((H, W), bool)
    inner[margin:H - margin, margin:W - margin] = True
    where = np.asarray(where, bool) & inner
    s = np.asarray(start, dtype=np.float64).copy()
    if int(np.count_nonzero(where)) < MIN_QUIET:
        return s

    def detail(img: np.ndarray) -> np.ndarray:
        d = np.float32(img) - cv2.GaussianBlur(np.float32(img), (0, 0), blur_px)
        return d / np.sqrt(cv2.GaussianBlur(d * d, (0, 0), blur_px) + 1e-12)

    read, rng = interpolation("bandlimited"), np.random.default_rng(0)
    tiles = grown_tiles(where, margin)
    parts = []  # per tile: the reference's picture, its pixels (P, 2) in the tile, the distorted image there (P,)
    for (rows, cols), grown in tiles:
        r, c = np.nonzero(where[rows, cols])
        if len(r) > POINTS // len(tiles):
            pick = rng.choice(len(r), POINTS // len(tiles), replace=False)
            r, c = r[pick], c[pick]
        r, c = r + rows.start - grown[0].start, c + cols.start - grown[1].start
        parts.append((read.grid(torch.as_tensor(detail(reference[grown]), dtype=torch.float64)),
                      torch.as_tensor(np.stack([c, r], -1), dtype=torch.float64),
                      torch.as_tensor(detail(distorted[grown])[r, c], dtype=torch.float64)))
    h = 0.1  # px: the central difference of a picture smooth over several pixels
    steps = [torch.tensor([h, 0.0], dtype=torch.float64), torch.tensor([0.0, h], dtype=torch.float64)]
    for _ in range(iterations):
        JTJ, JTr = torch.zeros(2, 2, dtype=torch.float64), torch.zeros(2, dtype=torch.float64)
        for grid, x, d in parts:
            at = x + torch.as_tensor(s)
            J = torch.stack([(read.at(grid, at + e) - read.at(grid, at - e)) / (2 * h) for e in steps], -1)
            JTJ, JTr = JTJ + J.T @ J, JTr + J.T @ (read.at(grid, at) - d)
        step = torch.linalg.solve(JTJ, -JTr).numpy()
        s += step
        if np.abs(step).max() < 1e-4:
            break
    return s
