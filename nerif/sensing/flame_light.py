"""The flame's own light on a distorted exposure. Many rigs record each view once more with the background
switched off: that exposure is the flame's light alone (plus the sensor's dark level), which is taken off. Where
none was recorded, the light is seen as a local brightening of the distorted exposure over its reference that an
illumination drift (smooth across the view) does not explain."""
from __future__ import annotations

import cv2
import numpy as np

LIGHT_SEEN = 0.02  # light_structure above this: the flame's light is seen (clean pairs: 0.003, 1 % noise)
DRIFT_PX = 16.0  # a brightness change smoother than this [px] is the illumination's, which normalisation takes off


def without_flame_light(distorted: np.ndarray, flame: np.ndarray) -> np.ndarray:
    """(H, W) ``distorted`` less the flame's light: ``flame`` (H, W), the same view with the background off, less its
    dark level (its median: the flame covers a small part of the view), so that the distorted image keeps its own
    dark level. Intensities in [0, 1] of full scale."""
    flame = np.asarray(flame, dtype=np.float32)
    return np.asarray(distorted, dtype=np.float32) - (flame - np.float32(np.median(flame)))


def light_structure(distorted: np.ndarray, reference: np.ndarray, width_px: float) -> float:
    """How much light the distorted exposure (H, W) has over its reference (H, W) with structure finer than an
    illumination drift: the local means of both over 4 texture widths ``width_px`` (the texture averages out), their
    relative difference less its Gaussian blur of :data:`DRIFT_PX`, its 99.5th percentile of magnitude (a share of the
    local brightness). Measured: 0.003 on the shared clean captures' nine views (1 % noise, displacements up to
    0.5 px), 0.047 on the dirty capture's (light 30 % of the background's mean, blurred by 2 px)."""
    d, r = np.float32(distorted), np.float32(reference)
    window = 4.0 * float(width_px)
    mean_d, mean_r = cv2.GaussianBlur(d, (0, 0), window), cv2.GaussianBlur(r, (0, 0), window)
    q = (mean_d - mean_r) / np.maximum(mean_r, 0.05 * float(np.median(mean_r)) + 1e-6)
    return float(np.percentile(np.abs(q - cv2.GaussianBlur(q, (0, 0), DRIFT_PX)), 99.5))
