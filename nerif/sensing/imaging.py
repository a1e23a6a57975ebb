"""Image formation of a BOS camera: the background warped by displacements, diffraction blur, sensor noise.

Images are (H, W) float tensors with intensities in [0, 1]; displacements are (H, W, 2) [px] as
(column, row), meaning that pixel ``x`` shows the background at ``x + u(x)``.
"""
from __future__ import annotations

from typing import Optional

import cv2
import kornia
import numpy as np
import torch


def warp(image: torch.Tensor, u: torch.Tensor, mode: str = "bicubic") -> torch.Tensor:
    """The background seen through displacements ``u``: ``out(x) = image(x + u(x))`` (differentiable).

    Args:
        image: (H, W). u: (H, W, 2) [px] (column, row).
    Returns:
        (H, W); pixels that look past the image border read the border value.
    """
    H, W = image.shape
    rows, cols = torch.meshgrid(torch.arange(H, dtype=u.dtype, device=u.device),
                                torch.arange(W, dtype=u.dtype, device=u.device), indexing="ij")
    out = kornia.geometry.transform.remap(image[None, None], (cols + u[..., 0])[None], (rows + u[..., 1])[None],
                                          mode=mode, padding_mode="border", align_corners=True)
    return out[0, 0]


def expose(background: torch.Tensor, u: Optional[torch.Tensor], samples: int, band_rows: int = 64) -> torch.Tensor:
    """What a camera's pixels record of a background seen through displacements ``u``: each pixel the mean of the
    background at its ``samples x samples`` sub-pixel points, each point moved by ``u`` interpolated to it
    (bilinear) and the background read there (bilinear on its fine grid), as a pixel integrates the light over
    its area. The exposure of :func:`warp` (``samples`` 1) reads a pixel-sampled pattern at the displaced centre
    instead, by the same kind of interpolation the image term models a view with.

    Args:
        background: (H s, W s) the pattern on a grid ``s = samples`` times finer than the pixels (sample ``j`` at
            ``(j + 0.5) / s - 0.5`` px). u: (H, W, 2) [px] (column, row), or None for the undisplaced reference.
        band_rows: pixel rows done at a time (memory: about 40 s^2 W bytes a row).
    Returns:
        (H, W); points past the border read the border value.
    """
    s = samples
    H, W = background.shape[0] // s, background.shape[1] // s
    fine = background[None, None]
    if u is None:
        return torch.nn.functional.avg_pool2d(fine, s)[0, 0]
    field = u.permute(2, 0, 1)[None].to(background.dtype)  # (1, 2, H, W)
    cols = (torch.arange(W * s, dtype=background.dtype) + 0.5) / s - 0.5  # sub-pixel points [px of the pixels]
    out = background.new_empty(H, W)
    for r0 in range(0, H, band_rows):
        r1 = min(H, r0 + band_rows)
        rows = (torch.arange(r0 * s, r1 * s, dtype=background.dtype) + 0.5) / s - 0.5
        R, C = torch.meshgrid(rows, cols, indexing="ij")
        du = kornia.geometry.transform.remap(field, C[None], R[None], mode="bilinear", padding_mode="border",
                                             align_corners=True)[0]  # (2, h s, W s) [px]
        seen = kornia.geometry.transform.remap(fine, ((C + du[0] + 0.5) * s - 0.5)[None],
                                               ((R + du[1] + 0.5) * s - 0.5)[None], mode="bilinear",
                                               padding_mode="border", align_corners=True)
        out[r0:r1] = torch.nn.functional.avg_pool2d(seen, s)[0, 0]
    return out


def diffraction_blur(image: torch.Tensor, d_diff_px: float) -> torch.Tensor:
    """Blur by the Airy disc of diameter ``d_diff_px`` (to first zero), as a Gaussian of sigma 0.42 lambda N (1+M)
    = ``0.172 d_diff``. (H, W) -> (H, W)."""
    sigma = 0.42 / 2.44 * d_diff_px
    if sigma < 0.05:
        return image
    k = 2 * int(3 * sigma + 0.5) + 1
    return kornia.filters.gaussian_blur2d(image[None, None], (k, k), (sigma, sigma), border_type="reflect")[0, 0]


def add_noise(image: torch.Tensor, variance: float, generator: Optional[torch.Generator] = None) -> torch.Tensor:
    """Additive Gaussian sensor noise of ``variance`` (intensity units^2), reproducible under ``generator``."""
    if variance < 0:
        raise ValueError(f"noise variance must be >= 0, got {variance}")
    if variance == 0:
        return image
    noise = torch.randn(image.shape, generator=generator, dtype=image.dtype, device=image.device)
    return image + variance**0.5 * noise


def resample(u: np.ndarray, height: int, width: int) -> np.ndarray:
    """(h, w, C) or (h, w) field -> (height, width, C) or (height, width), pixel centres aligned: block mean when
    shrinking, bilinear else."""
    if u.shape[:2] == (height, width):
        return u
    shrink = height < u.shape[0]
    out = cv2.resize(u, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    return out.reshape((height, width) + u.shape[2:])  # OpenCV drops a single channel's axis


def shrunk(image: np.ndarray, factor: int) -> np.ndarray:
    """(H, W) -> (H // factor, W // factor) area means (the image itself for 1): a texture ``factor`` times finer in
    pixels, the noise averaged down."""
    if factor == 1:
        return image
    H, W = image.shape
    return cv2.resize(np.float32(image), (max(W // factor, 1), max(H // factor, 1)), interpolation=cv2.INTER_AREA)


def enlarged(a: np.ndarray, H: int, W: int) -> np.ndarray:
    """A mask (h, w) bool (nearest) or a flow (h, w, 2) [px of that grid] (bilinear, scaled by the size ratio) on
    shrunk images (:func:`shrunk`) brought to (H, W)."""
    h, w = a.shape[:2]
    if (h, w) == (H, W):
        return a
    if a.dtype == bool:
        return cv2.resize(a.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST).astype(bool)
    return cv2.resize(a, (W, H), interpolation=cv2.INTER_LINEAR) * np.float32([W / w, H / h])
