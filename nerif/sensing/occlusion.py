"""Occluders: a burner, a mount, a probe in front of the background. Where the background is hidden the reference
image has no texture, and a flow vector there is noise; a ray there is blocked, not a ray that crossed empty gas."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np
from scipy import ndimage

from nerif.sensing.texture import texture_width


GAP = 1  # the radius [texture widths] of the widest sparse patch of a random pattern: an area without texture
# narrower than twice it is a gap between dots, not an occluder
GAPS_COUNTED = 20  # areas without texture from which a view's own gap sizes are read (:func:`gap_radius`)
GAP_FACTOR = 3.0  # an occluder's inscribed radius over the upper quartile of the pattern's gaps', at least
CHANCE = 0.1  # the expected number of a pattern's own gaps wider than the bar (:func:`gap_radius`)


def local_contrast(image: np.ndarray, width_px: float) -> np.ndarray:
    """(H, W) the RMS of ``image``'s detail (less its Gaussian blur of ``width_px``) over a Gaussian window of
    ``width_px``."""
    img = np.float32(image)
    detail = img - cv2.GaussianBlur(img, (0, 0), float(width_px))
    return np.sqrt(cv2.GaussianBlur(detail * detail, (0, 0), float(width_px)))


def occluded(reference: np.ndarray, fraction: float = 0.25, width_px: Optional[float] = None,
             contrast: Optional[np.ndarray] = None) -> np.ndarray:
    """(H, W) bool: the pixels where ``reference`` (H, W) shows no texture: its :func:`local_contrast` over the
    texture's own scale (the flow's normalisation width, :func:`nerif.sensing.texture.texture_width`) below
    ``fraction`` of the background's contrast (the view's median, or half that of its best-textured tenth where
    most of the view is hidden), in the areas wider than the pattern's own gaps (:func:`gap_radius`), grown by 3
    widths (the contrast window and the flow's window reach that far across the occluder's edge). Where the
    pattern has no gaps of its own (fewer than :data:`GAPS_COUNTED` textureless areas) each such area is kept
    whole, a model with its sting; where it has, what of them the discs wider than its gaps cover (an opening):
    the pattern's gaps that touch an object are not the object (on random dots 0.005-0.01 a px, 9-22 % of the
    pattern was taken with a model and a blurred band, none now: ``benchmarks/occlusion.py``). A speckle
    background keeps its contrast within a factor of two or so across the image (illumination falls off
    smoothly); a dark burner tube or mount has none. On the shared dirty capture's burner (5.4 % of each image):
    0.02 % of its pixels missed, none taken beside it. ``width_px``: the texture's width, and
    ``contrast`` (H, W) the reference's :func:`local_contrast` over it, where the caller has them."""
    width = width_px or texture_width(reference)
    c = local_contrast(reference, width) if contrast is None else contrast
    # the background's contrast: the median, unless most of the view is hidden (then half its best-textured tenth's)
    level = max(float(np.median(c)), 0.5 * float(np.percentile(c, 90)))
    if not level > 0:
        return np.zeros(c.shape, bool)
    hidden = (c < fraction * level).astype(np.uint8)
    if not hidden.any():
        return hidden > 0
    n, labels, inscribed = inscribed_radii(hidden)
    bar = gap_radius(inscribed, width)
    if len(inscribed) < GAPS_COUNTED:  # a pattern without gaps: each area wider than the bar, whole (a sting too)
        hidden = np.isin(labels, np.arange(1, n)[inscribed > bar]).astype(np.uint8)
    else:  # the discs wider than the pattern's gaps that fit (an opening): without the gaps that touch an object
        body = np.uint8(depth_px(hidden) > bar)
        hidden = np.uint8(cv2.distanceTransform(1 - body, cv2.DIST_L2, 5) <= bar + 1) & hidden
    margin = int(np.ceil(3 * width))
    if hidden.any():
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
        hidden = cv2.dilate(hidden, disc)
    return hidden > 0


def depth_px(hidden: np.ndarray) -> np.ndarray:
    """(H, W) float32: each pixel of ``hidden`` (H, W) uint8's distance [px] to the nearest pixel outside it, the
    image's edge counting as outside (an area along the edge is as wide as it is, not twice)."""
    padded = cv2.copyMakeBorder(hidden, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    return cv2.distanceTransform(padded, cv2.DIST_L2, 5)[1:-1, 1:-1]


def inscribed_radii(hidden: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """The connected areas of ``hidden`` (H, W) uint8 (8-connected): their count + 1, their labels (H, W) and each
    one's inscribed radius [px] (n - 1,) (:func:`depth_px`)."""
    n, labels = cv2.connectedComponents(hidden, connectivity=8)
    depth = depth_px(hidden)
    return n, labels, np.asarray(ndimage.maximum(depth, labels, np.arange(1, n)), dtype=np.float64).reshape(-1)


def gap_radius(inscribed: np.ndarray, width_px: float) -> float:
    """The radius [px] of the widest area without texture that the pattern shows by chance (``inscribed``: each
    area's inscribed radius, px): :data:`GAP` texture widths, or where the view holds at least
    :data:`GAPS_COUNTED` such areas, the larger of :data:`GAP_FACTOR` times their upper quartile and the radius
    that :data:`CHANCE` of them pass, their tail read from the median and the upper quartile as exponential
    (``P(r > x) = exp(-(x - median) ln 2 / (q3 - median)) / 2``; a regular grid's gaps, all alike: one texture
    width past them).

    A random pattern's sparse patches are many and alike (their sizes set by its dots' density, which the
    texture's width does not tell: a pattern of sparse dots 7 px apart has a width of 2.2 px and gaps 10 px
    wide); an occluder is one area far wider. The bar is read from the median and the quartile, which a few
    objects (a model, its sting, a blurred band: up to a quarter of the areas) do not move; a bar from the 95th
    percentile (issue 56) was set by the objects themselves where the view held 20-100 areas, and a real model on
    a dot grid went unseen (issue 70). Measured on uniformly random dots (0.005-0.1 a px, 1-3 px radius, 512-2048
    px square) and regular grids: no pattern pixel taken; a plate, a burner and a blurred band found whole
    (``tests/test_occlusion.py``, ``benchmarks/occlusion.py``). A rod narrower than the pattern's widest gaps
    cannot be told from them, and its vectors are left to the outlier test."""
    bar = np.ceil(GAP * width_px) + 0.5  # the distance transform's radius of a disc of ceil(GAP widths) px
    if len(inscribed) >= GAPS_COUNTED:
        median, q3 = np.percentile(inscribed, [50, 75])
        tail = (median + np.log(len(inscribed) / 2 / CHANCE) * (q3 - median) / np.log(2) if q3 > median
                else q3 + width_px)
        bar = max(bar, GAP_FACTOR * float(q3), float(tail))
    return float(bar)
