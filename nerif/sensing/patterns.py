"""Background patterns for BOS, rendered at sensor resolution.

Every pattern is ``fn(height, width, seed, samples=1, **params) -> (height * samples, width * samples) float32``
with intensities in [0, 1], registered in :data:`PATTERNS` and reproducible under its seed: the background as a
pixel grid of ``height x width`` sees it, sampled ``samples`` times finer along each axis (sample ``j`` of the
fine grid at ``(j + 0.5) / samples - 0.5`` px of the image), so that a camera's pixel can integrate it
(:func:`nerif.sensing.imaging.expose`). Lengths are in pixels of the image, whatever ``samples``.
"""
from __future__ import annotations

import cv2
import numpy as np

from nerif.registry import Registry

PATTERNS = Registry("background pattern", package="nerif.sensing")


def poisson_disk_points(height: int, width: int, spacing_px: float, rng: np.random.Generator,
                        rounds: int = 15) -> np.ndarray:
    """Points no closer than ``spacing_px`` to each other, filling the image (maximal Poisson-disk set).

    Parallel dart throwing on a grid of cells of side ``spacing / sqrt(2)`` (one point per cell at most):
    each round proposes a point in every empty cell of one of 9 phases (cells 3 apart cannot conflict) and
    keeps those farther than ``spacing`` from every point in the 5 x 5 cells around (gathered at once from the
    flattened grid: 4-7x faster than a gather per neighbour, the same points).
    Returns: (P, 2) points as (row, column) [px].
    """
    s = spacing_px / np.sqrt(2.0)
    ny, nx = int(np.ceil(height / s)), int(np.ceil(width / s))
    stride = nx + 4  # the grid padded by 2 cells on every side, flattened; a cell's point as (row, col), NaN: none
    row, col = np.full((ny + 4) * stride, np.nan), np.full((ny + 4) * stride, np.nan)
    around = np.array([dy * stride + dx for dy in range(-2, 3) for dx in range(-2, 3)])
    phases = [((cy + 2) * stride + cx + 2).ravel() for pi in range(3) for pj in range(3)
              for cy, cx in [np.meshgrid(np.arange(pi, ny, 3), np.arange(pj, nx, 3), indexing="ij")]]
    for _ in range(rounds):
        for cells in phases:
            cells = cells[np.isnan(row[cells])]
            if not len(cells):
                continue
            r = (cells // stride - 2 + rng.random(len(cells))) * s
            c = (cells % stride - 2 + rng.random(len(cells))) * s
            near = cells[:, None] + around
            d2 = (row[near] - r[:, None]) ** 2 + (col[near] - c[:, None]) ** 2
            ok = (r < height) & (c < width) & ~(d2 < spacing_px**2).any(1)  # NaN neighbours compare False
            row[cells[ok]], col[cells[ok]] = r[ok], c[ok]
    inside = np.zeros((ny + 4, stride), bool)
    inside[2:-2, 2:-2] = True
    keep = inside.ravel() & ~np.isnan(row)
    return np.stack([row[keep], col[keep]], -1)


def render_dots(height: int, width: int, points: np.ndarray, radius_px: float, samples: int = 1) -> np.ndarray:
    """Anti-aliased white discs of ``radius_px`` on black at ``points`` (row, column) [px] -> (H s, W s) float32
    (``s = samples`` a pixel and axis), each value the disc's cover of its sample's area (drawn on a grid at least
    4 and 2 s times finer than the pixels, then area means)."""
    k = samples * max(2, -(-4 // samples))
    canvas = np.zeros((height * k, width * k), np.uint8)
    shift = 4  # sub-pixel precision of cv2.circle: 2^-4 px
    centres = np.round((points * k + (k - 1) / 2) * (1 << shift)).astype(np.int64)
    r = int(round(radius_px * k * (1 << shift)))
    for y, x in centres:
        cv2.circle(canvas, (int(x), int(y)), r, 255, -1, lineType=cv2.LINE_8, shift=shift)
    return cv2.resize(canvas.astype(np.float32) / 255.0, (width * samples, height * samples),
                      interpolation=cv2.INTER_AREA)


@PATTERNS.register("poisson_disk")
def poisson_disk(height: int, width: int, seed: int = 0, samples: int = 1, spacing_px: float = 4.0,
                 radius_px: float = 1.2) -> np.ndarray:
    """Dots of ``radius_px`` at Poisson-disk positions (no two closer than ``spacing_px``): the paper's pattern."""
    rng = np.random.default_rng(seed)
    return render_dots(height, width, poisson_disk_points(height, width, spacing_px, rng), radius_px, samples)


@PATTERNS.register("random_dots")
def random_dots(height: int, width: int, seed: int = 0, samples: int = 1, density: float = 0.06,
                radius_px: float = 1.2) -> np.ndarray:
    """Dots of ``radius_px`` at uniformly random positions, ``density`` dots per pixel (overlaps allowed)."""
    rng = np.random.default_rng(seed)
    n = int(round(density * height * width))
    return render_dots(height, width, rng.random((n, 2)) * [height, width], radius_px, samples)


@PATTERNS.register("dot_grid")
def dot_grid(height: int, width: int, seed: int = 0, samples: int = 1, pitch_px: float = 8.0,
             radius_px: float = 2.0) -> np.ndarray:
    """Dots of ``radius_px`` on a regular square grid ``pitch_px`` apart, as wind tunnels print them: a pattern
    without gaps, every patch between the dots alike; the grid's phase drawn under ``seed``."""
    rng = np.random.default_rng(seed)
    rows, cols = (np.arange(-1.0, n / pitch_px + 1.0) * pitch_px + rng.random() * pitch_px for n in (height, width))
    r, c = np.meshgrid(rows, cols, indexing="ij")
    return render_dots(height, width, np.stack([r.ravel(), c.ravel()], -1), radius_px, samples)


@PATTERNS.register("wavelet_noise")
def wavelet_noise(height: int, width: int, seed: int = 0, samples: int = 1, scale_px: float = 2.0) -> np.ndarray:
    """Band-limited noise (Cook & DeRose wavelet noise): white noise minus its low-pass, at a feature size of
    about ``scale_px``; normalised to [0, 1] (1st-99th percentiles)."""
    rng = np.random.default_rng(seed)
    h, w = int(np.ceil(height / scale_px)) + 2, int(np.ceil(width / scale_px)) + 2
    h, w = h + h % 2, w + w % 2
    r = rng.standard_normal((h, w)).astype(np.float32)
    low = cv2.resize(cv2.resize(r, (w // 2, h // 2), interpolation=cv2.INTER_AREA), (w, h), interpolation=cv2.INTER_LINEAR)
    s = scale_px * samples
    band = cv2.resize(r - low, (int(round(w * s)), int(round(h * s))), interpolation=cv2.INTER_CUBIC)
    band = band[:height * samples, :width * samples]
    lo, hi = np.percentile(band, [1, 99])
    return np.clip((band - lo) / (hi - lo), 0, 1).astype(np.float32)
