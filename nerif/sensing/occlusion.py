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
GAP_FACTOR = 3.0  # an occluder's inscribed radius over the 95th percentile of the pattern's gaps'


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
    most of the view is hidden), in the areas wider than the pattern's own gaps (:func:`gap_radius`: each area kept
    whole or not at all), grown by 3 widths (the contrast window and the flow's window reach that far across the
    occluder's edge). A speckle background keeps its contrast within a factor of two or so across the image
    (illumination falls off smoothly); a dark burner tube or mount has none. On the shared dirty capture's burner
    (5.4 % of each image): 0.02 % of its pixels missed, none taken beside it. ``width_px``: the texture's width, and
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
    n, labels = cv2.connectedComponents(hidden, connectivity=8)
    inscribed = ndimage.maximum(cv2.distanceTransform(hidden, cv2.DIST_L2, 5), labels, np.arange(1, n))
    hidden = np.isin(labels, np.arange(1, n)[np.asarray(inscribed) > gap_radius(inscribed, width)]).astype(np.uint8)
    margin = int(np.ceil(3 * width))
    if hidden.any():
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
        hidden = cv2.dilate(hidden, disc)
    return hidden > 0


def gap_radius(inscribed: np.ndarray, width_px: float) -> float:
    """The radius [px] of the widest area without texture that a random pattern shows by chance: :data:`GAP`
    texture widths, or where the view holds at least :data:`GAPS_COUNTED` such areas, :data:`GAP_FACTOR` times the
    95th percentile of their inscribed radii (``inscribed``, px), if more: a random pattern's sparse patches are many
    and alike (their sizes set by its dots' density, which the texture's width does not tell: a pattern of sparse
    dots 7 px apart has a width of 2.2 px and gaps 10 px wide), an occluder is one area far wider. Measured on
    uniformly random dots (0.02-0.1 a px, 1-2.5 px radius, 640 x 640 px): no pattern pixel taken (0.1-22 % with a
    fixed width of one texture width), a dark mount 60 px wide found whole; a rod narrower than the pattern's
    widest gaps (18 px among dots 7 px apart) cannot be told from them, and its vectors are left to the outlier
    test."""
    bar = np.ceil(GAP * width_px) + 0.5  # the distance transform's radius of a disc of ceil(GAP widths) px
    if len(inscribed) >= GAPS_COUNTED:
        bar = max(bar, GAP_FACTOR * float(np.percentile(inscribed, 95)))
    return bar
