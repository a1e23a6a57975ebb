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


def to_uint8(image) -> "np.ndarray":
    """Intensities in [0, 1] -> 8-bit (rounded, clipped), as a camera saves them."""
    return np.clip(np.rint(np.asarray(image) * 255.0), 0, 255).astype(np.uint8)


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


def sample(image: torch.Tensor, x: torch.Tensor, mode: str = "bicubic") -> torch.Tensor:
    """The image at points ``x`` (P, 2) [px] (column, row; pixel centres at integers), differentiable in ``x``:
    (H, W) -> (P,). Points past the border read the border value."""
    H, W = image.shape
    scale = x.new_tensor([2.0 / max(W - 1, 1), 2.0 / max(H - 1, 1)])
    grid = (x * scale - 1.0).to(image.dtype)[None, None]  # (1, 1, P, 2), align_corners=True
    out = torch.nn.functional.grid_sample(image[None, None], grid, mode=mode, padding_mode="border",
                                          align_corners=True)
    return out[0, 0, 0]


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
