"""Displacement estimation between a distorted and a reference BOS image (OpenCV optical flow).

Every estimator is ``fn(distorted, reference, **params) -> (H, W, 2) float32 [px]`` (column, row) with
``distorted(x) ~ reference(x + u(x))``, the convention of :mod:`nerif.sensing.imaging`, registered in
:data:`FLOW`.
"""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np

from nerif.registry import Registry
from nerif.sensing.imaging import to_uint8

FLOW = Registry("optical flow", package="nerif.sensing")


AUTO_WIDTH_PER_SCALE = 1.5  # normalise_px=auto: this many of the texture's correlation lengths
AUTO_WIDTH_RANGE_PX = (1.5, 8.0)


def texture_scale_px(image: np.ndarray) -> float:
    """The correlation length [px] of a background's texture: for a random texture with a Gaussian
    autocorrelation of width ``l``, ``l = sqrt(2) std(I) / rms |grad I|``, taken on the image less its Gaussian blur
    of 8 px (its illumination). Measured: 1.45 px on the shared captures' texture, 1.34 and 1.40 on the Poisson-disk
    and wavelet patterns, 2.06 and 3.74 on the Poisson-disk pattern enlarged 2 and 4 times."""
    img = np.float32(image)
    detail = img - cv2.GaussianBlur(img, (0, 0), 8.0)
    gy, gx = np.gradient(detail)
    grad = float(np.sqrt(np.mean(gx * gx + gy * gy)))
    return float(np.sqrt(2.0) * detail.std() / grad) if grad > 0 else AUTO_WIDTH_RANGE_PX[1]


def normalise_width(setting, reference: np.ndarray) -> Optional[float]:
    """``normalise_px`` as a width [px]: ``auto`` is :data:`AUTO_WIDTH_PER_SCALE` correlation lengths of the
    reference's texture (:func:`texture_scale_px`) within :data:`AUTO_WIDTH_RANGE_PX`: as narrow as the texture
    allows, so that the flame's own light, defocused over a few pixels, drops out with the illumination (on the
    shared dirty capture, whose light is blurred by 2 px: the flow's error 3.4 px with 8 px, 0.061 px with 2 px;
    on the clean one 0.058 and 0.056 px)."""
    if setting != "auto":
        return setting
    lo, hi = AUTO_WIDTH_RANGE_PX
    return float(np.clip(AUTO_WIDTH_PER_SCALE * texture_scale_px(reference), lo, hi))


def normalised(image: np.ndarray, width_px: Optional[float]) -> np.ndarray:
    """``image`` (H, W) in [0, 1] locally normalised: less its Gaussian blur of ``width_px`` [px], over its local
    RMS contrast there, mapped back about 0.5 (contrast 0.15): a smooth brightness change between the exposures
    drops out, additive (the flame's own light) and multiplicative (an illumination drift) alike. None: as it is."""
    if not width_px:
        return image
    img = np.float32(image)
    detail = img - cv2.GaussianBlur(img, (0, 0), float(width_px))
    contrast = np.sqrt(cv2.GaussianBlur(detail * detail, (0, 0), float(width_px))) + 1e-6
    return np.clip(0.5 + 0.15 * detail / contrast, 0.0, 1.0)


@FLOW.register("farneback")
def farneback(distorted: np.ndarray, reference: np.ndarray, pyr_scale: float = 0.5, levels: int = 5,
              winsize: int = 7, iterations: int = 5, poly_n: int = 5, poly_sigma: float = 1.1,
              normalise_px="auto") -> np.ndarray:
    """Farneback's polynomial-expansion flow (defaults: the paper's parameters), on float32 images scaled to
    0-255 (its thresholds assume 8-bit intensities: on [0, 1] images it returns ~zero flow), each first
    :func:`normalised` over ``normalise_px`` where given (``auto``: :func:`normalise_width`)."""
    width = normalise_width(normalise_px, reference)
    d, r = (normalised(x, width) for x in (distorted, reference))
    return cv2.calcOpticalFlowFarneback(np.float32(d) * 255, np.float32(r) * 255, None,
                                        pyr_scale, levels, winsize, iterations, poly_n, poly_sigma, 0)


@FLOW.register("dis")
def dis(distorted: np.ndarray, reference: np.ndarray, preset: str = "medium", patch_size: int = 8,
        patch_stride: int = 3, refinement_iterations: int = 5, normalise_px: Optional[float] = None) -> np.ndarray:
    """Dense inverse search (Kroeger et al. 2016) with variational refinement, on 8-bit images, each first
    :func:`normalised` over ``normalise_px`` where given (``auto``: :func:`normalise_width`)."""
    width = normalise_width(normalise_px, reference)
    distorted, reference = (normalised(x, width) for x in (distorted, reference))
    presets = {"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
               "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}
    if preset not in presets:
        raise ValueError(f"DIS preset '{preset}' unknown; choose one of: {', '.join(presets)}")
    est = cv2.DISOpticalFlow_create(presets[preset])
    est.setPatchSize(patch_size)
    est.setPatchStride(patch_stride)
    est.setVariationalRefinementIterations(refinement_iterations)
    return est.calc(to_uint8(distorted), to_uint8(reference), None)
