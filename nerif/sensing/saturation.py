"""Saturated pixels: where either exposure reaches the sensor's top code value, the background's texture is lost
(the flame's own light, a reflection, a bright background), and neither the flow nor the image term can read a
displacement there."""
from __future__ import annotations

import cv2
import numpy as np

TOP = 1.0  # the full scale of images read as [0, 1] of their bit depth


def saturated(distorted: np.ndarray, reference: np.ndarray, margin_px: int = 1) -> np.ndarray:
    """(H, W) bool: the pixels at the top code value in either exposure (``distorted``, ``reference``: (H, W) in
    [0, 1] of full scale), dilated by ``margin_px`` (the flow's estimate at a pixel beside a clipped one reads it).
    Exactly the top: a sensor clips there; a rendered image's interpolation may overshoot it, which no sensor
    records."""
    clipped = (np.asarray(distorted) == TOP) | (np.asarray(reference) == TOP)
    if margin_px > 0 and clipped.any():
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * margin_px + 1, 2 * margin_px + 1))
        clipped = cv2.dilate(clipped.astype(np.uint8), disc) > 0
    return clipped
