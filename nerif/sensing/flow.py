"""Displacement estimation between a distorted and a reference BOS image (OpenCV optical flow).

Every estimator is ``fn(distorted, reference, **params) -> (H, W, 2) float32 [px]`` (column, row) with
``distorted(x) ~ reference(x + u(x))``, the convention of :mod:`nerif.sensing.imaging`, registered in
:data:`FLOW`.
"""
from __future__ import annotations

import cv2
import numpy as np

from nerif.registry import Registry
from nerif.sensing.imaging import to_uint8

FLOW = Registry("optical flow", package="nerif.sensing")


@FLOW.register("farneback")
def farneback(distorted: np.ndarray, reference: np.ndarray, pyr_scale: float = 0.5, levels: int = 5,
              winsize: int = 7, iterations: int = 5, poly_n: int = 5, poly_sigma: float = 1.1) -> np.ndarray:
    """Farneback's polynomial-expansion flow (defaults: the paper's parameters), on float32 images scaled to
    0-255 (its thresholds assume 8-bit intensities: on [0, 1] images it returns ~zero flow)."""
    return cv2.calcOpticalFlowFarneback(np.float32(distorted) * 255, np.float32(reference) * 255, None,
                                        pyr_scale, levels, winsize, iterations, poly_n, poly_sigma, 0)


@FLOW.register("dis")
def dis(distorted: np.ndarray, reference: np.ndarray, preset: str = "medium", patch_size: int = 8,
        patch_stride: int = 3, refinement_iterations: int = 5) -> np.ndarray:
    """Dense inverse search (Kroeger et al. 2016) with variational refinement, on 8-bit images."""
    presets = {"ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
               "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM}
    if preset not in presets:
        raise ValueError(f"DIS preset '{preset}' unknown; choose one of: {', '.join(presets)}")
    est = cv2.DISOpticalFlow_create(presets[preset])
    est.setPatchSize(patch_size)
    est.setPatchStride(patch_stride)
    est.setVariationalRefinementIterations(refinement_iterations)
    return est.calc(to_uint8(distorted), to_uint8(reference), None)
