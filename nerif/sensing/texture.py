"""The statistics of a background's texture that the measurement stage's steps share: its correlation length, the
width over which its detectors look and the flow normalises, and how many times smaller a fine camera's images are
made for the flow (:mod:`nerif.sensing.measurement`)."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

AUTO_WIDTH_PER_SCALE = 1.5  # normalise_px=auto: this many of the texture's correlation lengths
AUTO_WIDTH_RANGE_PX = (1.5, 8.0)


def texture_scale_px(image: np.ndarray) -> float:
    """The correlation length [px] of a background's texture: for a random texture with a Gaussian
    autocorrelation of width ``l``, ``l = sqrt(2) std(I) / rms |grad I|``, taken on the image less its Gaussian blur
    of 8 px (its illumination), or of 4 such lengths where that is more (a coarse texture, of which a blur of 8 px
    takes a part for illumination). Measured: 1.45 px on the shared captures' texture, 1.34 and 1.40 on the
    Poisson-disk and wavelet patterns; 3.19 on the shared flame written at 4x finer pixels and 7.2 at 10.5x finer
    (3.12 and 5.31 over 8 px alone)."""
    img = np.float32(image)

    def scale(blur_px: float) -> float:
        detail = img - cv2.GaussianBlur(img, (0, 0), blur_px)
        gy, gx = np.gradient(detail)
        grad = float(np.sqrt(np.mean(gx * gx + gy * gy)))
        return float(np.sqrt(2.0) * detail.std() / grad) if grad > 0 else AUTO_WIDTH_RANGE_PX[1]

    first = scale(8.0)
    return scale(4 * first) if 4 * first > 8.0 else first


def texture_width(reference: np.ndarray, scale_px: Optional[float] = None) -> float:
    """The texture's own width [px]: :data:`AUTO_WIDTH_PER_SCALE` correlation lengths of ``reference``'s texture
    (:func:`texture_scale_px`, or ``scale_px`` where the caller has it) within :data:`AUTO_WIDTH_RANGE_PX`; the
    scale over which the detectors of :mod:`nerif.sensing.measurement` look, and the flow's normalisation where the
    flame's light is seen."""
    lo, hi = AUTO_WIDTH_RANGE_PX
    scale = texture_scale_px(reference) if scale_px is None else scale_px
    return float(np.clip(AUTO_WIDTH_PER_SCALE * scale, lo, hi))


TUNED_SCALE_PX = 1.45  # the texture's correlation length the flows' settings are tuned for (the shared captures')


def shrink_factor(scale_px: float, setting) -> int:
    """How many times smaller the images are made for the flow: ``setting``, or for ``auto`` the texture's
    correlation length ``scale_px`` (:func:`texture_scale_px`) over :data:`TUNED_SCALE_PX`,
    rounded down:
    1 on the shared captures (1.45 px) and nerif's patterns (1.34-1.54 px), 2 on a 4x finer camera's images of the
    same background (3.19 px: sigma error 0.089 with the flow alone, 0.153 on the images as they are), 5 at 10.5x
    finer (7.34 px: 0.077, 0.080 with 3). On the Poisson-disk pattern enlarged k times (1.34, 2.07, 2.89, 3.76,
    5.50, 9.45 px for k = 1, 2, 3, 4, 6, 10.5: factors 1, 1, 1, 2, 3, 6) about k / 2 measures best (k = 4: 0.0058 px
    of error a pixel of the k = 1 grid with 2, 0.0097 with 3, 0.019 with 1; k = 3: 0.0081 with 1 and 0.0082 with 2;
    k = 10.5: 0.0053, 0.0054, 0.0064 with 4, 5, 6, 0.014 with 3)."""
    if setting == "auto":
        return max(1, int(scale_px / TUNED_SCALE_PX))
    if not (isinstance(setting, int) and setting >= 1):
        raise ValueError(f"measure.flow_factor={setting!r}: a whole number (the images made that many times smaller "
                         "for the flow; 1: as they are) or auto")
    return setting
