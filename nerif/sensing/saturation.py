"""Saturated pixels: where either exposure reaches the sensor's top code value over an area without texture, the
background is lost (the flame's own light, a reflection), and neither the flow nor the image term can read a
displacement there. Clipping alone loses nothing where texture remains: the bright dots of a pattern often clip at
their centres (the dots' edges carry the texture), and a bright background clips between its dark dots (the dots
carry it); neither is counted."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from nerif.sensing.texture import texture_width

TOP = 1.0  # the full scale of images read as [0, 1] of their bit depth


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def saturated(distorted: np.ndarray, reference: np.ndarray, margin_px: int = 1,
              width_px: Optional[float] = None, fraction: float = 0.05) -> np.ndarray:
    """(H, W) bool: where clipping takes the background's texture away in either exposure (``distorted``,
    ``reference``: (H, W) in [0, 1] of full scale): the pixels at the top code value where fewer than ``fraction``
    of the pixels around (a Gaussian window of two of the texture's widths,
    :func:`~nerif.sensing.texture.texture_width`; ``width_px`` where the caller has it) are below it, within a clipped area wider than two such widths (a
    morphological opening), with the clipped pixels around such a core (six widths, as far as the window reaches), and ``margin_px`` beyond (the flow's estimate at a pixel beside
    a clipped one reads it). A bright background clipped between dark dots keeps its texture (the dots carry it; on
    the shared real pair, 24 % of the reference clipped: 0.07 % counted), and so do the clipped centres of a
    pattern's bright dots: neither is counted. Exactly the top: a sensor clips there; a rendered image's
    interpolation may overshoot it, which no sensor records."""
    lost = np.zeros(np.shape(reference), np.uint8)
    exposures = [np.asarray(e) == TOP for e in (distorted, reference)]
    if not any(c.any() for c in exposures):
        return lost > 0
    width = width_px or texture_width(reference)
    radius = int(np.ceil(width))
    for clipped in exposures:
        if not clipped.any():
            continue
        below = cv2.GaussianBlur((~clipped).astype(np.float32), (0, 0), 2.0 * width)  # the texture's carriers around
        wide = cv2.morphologyEx(clipped.astype(np.uint8), cv2.MORPH_OPEN, _disc(radius)) > 0
        core = (wide & (below < fraction)).astype(np.uint8)
        if core.any():  # the clipped pixels of the textureless area, to its edge
            lost |= (clipped & (cv2.dilate(core, _disc(6 * radius)) > 0)).astype(np.uint8)
    if margin_px > 0 and lost.any():
        lost = cv2.dilate(lost, _disc(margin_px))
    return lost > 0
