"""Occluders: a burner, a mount, a probe in front of the background. Where the background is hidden the reference
image has no texture, and a flow vector there is noise; a ray there is blocked, not a ray that crossed empty gas."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from nerif.sensing.texture import texture_width


GAP = 1  # the radius [texture widths] of the widest sparse patch of a random pattern: an area without texture
# narrower than twice it is a gap between dots, not an occluder


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
    most of the view is hidden), in the areas that hold a disc of :data:`GAP` such widths (a morphological opening,
    each area kept whole: the sparse patches of a random pattern, which show no texture over a width or two, are
    not occluders), grown by 3 widths (the contrast window and the flow's window
    reach that far across the occluder's edge). A speckle background keeps its contrast within a factor of two or so
    across the image (illumination falls off smoothly); a dark burner tube or mount has none. On the shared dirty capture's burner (5.4 % of each image):
    0.02 % of its pixels missed, none taken beside it. ``width_px``: the texture's width, and ``contrast`` (H, W)
    the reference's :func:`local_contrast` over it, where the caller has them."""
    width = width_px or texture_width(reference)
    c = local_contrast(reference, width) if contrast is None else contrast
    # the background's contrast: the median, unless most of the view is hidden (then half its best-textured tenth's)
    level = max(float(np.median(c)), 0.5 * float(np.percentile(c, 90)))
    if not level > 0:
        return np.zeros(c.shape, bool)
    hidden = (c < fraction * level).astype(np.uint8)
    if hidden.any():  # only areas wider than a random pattern's sparse patches, whole (a reconstruction)
        gap = int(np.ceil(GAP * width))
        core = cv2.morphologyEx(hidden, cv2.MORPH_OPEN,
                                cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * gap + 1, 2 * gap + 1)))
        _, labels = cv2.connectedComponents(hidden, connectivity=8)
        wide = np.unique(labels[core > 0])
        hidden = np.isin(labels, wide[wide > 0]).astype(np.uint8)
    margin = int(np.ceil(3 * width))
    if hidden.any():
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin + 1, 2 * margin + 1))
        hidden = cv2.dilate(hidden, disc)
    return hidden > 0
