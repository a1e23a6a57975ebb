"""The images' sensor noise, read from a view's two exposures: where the view sees no flame, the distorted exposure
is the reference seen through the flow (the camera's shake, nothing else) plus both exposures' noise. What is left
there is the noise an image data term cannot explain, the yardstick its residuals are weighed by
(:class:`nerif.solvers.data_terms.ImageTerm`). Several exposures per view measure it directly
(:func:`nerif.data.capture_images.exposure_noise`)."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np
from scipy import ndimage

MIN_PIXELS = 1000  # fewer usable pixels than this read no noise
FLOOR = 1e-3  # noise below this [share of full scale] weighs as this: no camera records less (an 8-bit step is 0.11 %,
              # the shot noise of a full well of 100 000 electrons 0.3 %); images rendered without noise read 1e-6
BLUR_WIDTHS = 4.0  # brightness and gain are taken as smooth over this many texture widths
MAD_TO_STD = 1.4826  # a Gaussian's standard deviation per median absolute deviation
TILE_PX = 512  # images larger than TILES tiles of this size are read on the tiles that hold the most usable pixels
TILES = 16
LOWPASS_PX = 2.0  # both exposures blurred by a Gaussian of this width [px] before they are compared: what a
# sub-pixel shift leaves of a pattern sharper than its pixels (aliasing, which no reading between the pixels undoes:
# 0.4 % of full scale for each 0.1 px of shake on a Poisson-disk pattern) lies above it; the share of a white
# noise's variance that passes is measured (:func:`_white_share`) and divided out. Against 1.5 px, on nerif's chain
# with 1 % sensor noise every dirt together 1.11x -> 1.08x its clean sigma error, on the 13 independent captures a
# geometric mean of 0.999, the peak's mean error unchanged (benchmarks/RESULTS.md, issue 70)


def _residual(distorted: np.ndarray, reference: np.ndarray, u: np.ndarray, width_px: float) -> np.ndarray:
    """(H, W) ``distorted`` less ``reference(x + u)`` (its cubic B-spline), both less their blur over
    :data:`BLUR_WIDTHS` texture widths, the reference's detail scaled by the local gain that fits it best (over the
    same window): the flame's light, a drift or a gain ramp between the exposures is no noise."""
    H, W = reference.shape
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float32)
    u = np.nan_to_num(np.asarray(u, dtype=np.float32))
    seen = ndimage.map_coordinates(np.float32(reference), [rows + u[..., 1], cols + u[..., 0]], order=3,
                                   mode="mirror")
    s = BLUR_WIDTHS * float(width_px)

    def blur(img):
        return cv2.GaussianBlur(img, (0, 0), s)

    d = _lowpass(np.float32(distorted))
    d = d - blur(d)
    seen = _lowpass(seen)
    w = seen - blur(seen)
    gain = blur(d * w) / np.maximum(blur(w * w), 1e-12)
    return d - gain * w


def _lowpass(image: np.ndarray) -> np.ndarray:
    return cv2.GaussianBlur(image, (0, 0), LOWPASS_PX)


def _white_share(width_px: float) -> float:
    """The share of a white noise's variance that :func:`_residual`'s filters (the low-pass of :data:`LOWPASS_PX`,
    less the blur over :data:`BLUR_WIDTHS` texture widths ``width_px``) let through, measured on 256 x 256 px of it."""
    n = np.random.default_rng(0).standard_normal((256, 256)).astype(np.float32)
    d = _lowpass(n)
    d = d - cv2.GaussianBlur(d, (0, 0), BLUR_WIDTHS * float(width_px))
    return float(d[32:-32, 32:-32].var() / n.var())


def _tiles(where: np.ndarray) -> list[tuple[slice, slice]]:
    """The image whole, or the :data:`TILES` tiles of :data:`TILE_PX` holding the most of ``where`` (H, W)."""
    H, W = where.shape
    if H * W <= TILES * TILE_PX**2:
        return [(slice(0, H), slice(0, W))]
    tiles = [(slice(r, min(r + TILE_PX, H)), slice(c, min(c + TILE_PX, W)))
             for r in range(0, H, TILE_PX) for c in range(0, W, TILE_PX)]
    return sorted(tiles, key=lambda t: -int(np.count_nonzero(where[t])))[:TILES]


def grown_tiles(where: np.ndarray, margin: int) -> list[tuple[tuple[slice, slice], tuple[slice, slice]]]:
    """Per tile of :func:`_tiles` (the image whole, or the tiles holding the most of ``where`` (H, W)): the tile and
    the tile grown by ``margin`` px on each side within the image (what its filters need read)."""
    H, W = where.shape
    return [((rows, cols), (slice(max(rows.start - margin, 0), min(rows.stop + margin, H)),
                            slice(max(cols.start - margin, 0), min(cols.stop + margin, W))))
            for rows, cols in _tiles(where)]


def residual_noise(distorted: np.ndarray, reference: np.ndarray, u: np.ndarray, where: Optional[np.ndarray] = None,
                   width_px: float = 2.0) -> Optional[float]:
    """One exposure's noise [share of full scale]: the robust RMS (1.4826 median absolute deviations) of what the
    flow ``u`` leaves of ``distorted`` (the reference seen through it, a smooth brightness and gain change taken
    off over :data:`BLUR_WIDTHS` texture widths ``width_px``), over the pixels ``where`` (H, W) bool (None: all),
    divided by sqrt 2: both exposures carry noise of one level. The median keeps what the flow misses on a few
    pixels out of it. None where fewer than :data:`MIN_PIXELS` pixels are given. An image larger than 4 megapixels
    is read on its 16 tiles of 512 px that hold the most of ``where`` (a second a view at 25 megapixels).

    Args:
        distorted, reference: (H, W) the two exposures, in [0, 1] of full scale.
        u: (H, W, 2) the flow between them [px] (column, row).
    """
    where = np.ones(reference.shape, bool) if where is None else np.asarray(where, dtype=bool)
    if int(np.count_nonzero(where)) < MIN_PIXELS:
        return None
    parts = []
    for (rows, cols), grown in grown_tiles(where, int(np.ceil(3 * BLUR_WIDTHS * width_px))):
        r = _residual(distorted[grown], reference[grown], u[grown], width_px)
        inner = (slice(rows.start - grown[0].start, rows.stop - grown[0].start),
                 slice(cols.start - grown[1].start, cols.stop - grown[1].start))
        parts.append(r[inner][where[rows, cols]])
    r = np.concatenate(parts)
    r = r[np.isfinite(r)]
    if r.size < MIN_PIXELS:
        return None
    return float(MAD_TO_STD * np.median(np.abs(r - np.median(r))) / np.sqrt(2.0 * _white_share(width_px)))
