"""The flame's own light on a distorted exposure. Many rigs record each view once more with the background
switched off: that exposure is the flame's light alone (plus the sensor's dark level), which is taken off."""
from __future__ import annotations

import numpy as np


def without_flame_light(distorted: np.ndarray, flame: np.ndarray) -> np.ndarray:
    """(H, W) ``distorted`` less the flame's light: ``flame`` (H, W), the same view with the background off, less its
    dark level (its median: the flame covers a small part of the view), so that the distorted image keeps its own
    dark level. Intensities in [0, 1] of full scale."""
    flame = np.asarray(flame, dtype=np.float32)
    return np.asarray(distorted, dtype=np.float32) - (flame - np.float32(np.median(flame)))
