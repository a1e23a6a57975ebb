"""Saturated pixels: where either exposure reaches the sensor's top code value over an area, the background's
texture is lost (the flame's own light, a reflection, a bright background), and neither the flow nor the image term
can read a displacement there. The bright dots of a pattern often clip at their centres; that loses no texture (the
dots' edges carry it) and is not counted."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from nerif.sensing.texture import texture_width

TOP = 1.0  # the full scale of images read as [0, 1] of their bit depth


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def saturated(distorted: np.ndarray, reference: np.ndarray, margin_px: int = 1,
              width_px: Optional[float] = None) -> np.ndarray:
    """(H, W) bool: the areas at the top code value in either exposure (``distorted``, ``reference``: (H, W) in
    [0, 1] of full scale) wider than two of the texture's widths (:func:`nerif.sensing.texture.texture_width`: a
    morphological opening takes off the clipped centres of the pattern's dots), dilated by ``margin_px`` (the flow's
    estimate at a pixel beside a clipped one reads it); ``width_px``: that width where the caller has it. Exactly the top: a sensor clips there; a rendered image's
    interpolation may overshoot it, which no sensor records."""
    clipped = ((np.asarray(distorted) == TOP) | (np.asarray(reference) == TOP)).astype(np.uint8)
    if not clipped.any():
        return clipped > 0
    radius = int(np.ceil(width_px or texture_width(reference)))
    core = cv2.morphologyEx(clipped, cv2.MORPH_OPEN, _disc(radius))
    _, labels = cv2.connectedComponents(clipped, connectivity=8)
    wide = np.unique(labels[core > 0])  # the clipped areas the opening leaves a core of, whole
    area = np.isin(labels, wide[wide > 0]).astype(np.uint8)
    if margin_px > 0 and area.any():
        area = cv2.dilate(area, _disc(margin_px))
    return area > 0
