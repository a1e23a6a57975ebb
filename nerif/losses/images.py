"""The image data term's building blocks: the photometric residual of a warped reference image, displacements
interpolated inside a cell of the ray grid, and the scale that puts the residual in the unit of a deflection
misfit.

Brightness constancy: pixel ``x`` of the distorted image shows the reference background at ``x + u(x)``, so
``r(x) = I_ref(x + u(x)) - I_dist(x)`` is sensor noise where ``u`` is right. Near the right ``u``,
``r = grad I_ref . du + noise``: averaged over the direction of du, ``E[r^2] = |grad I|^2 / 2 |du|^2 + 2 noise^2``,
which :func:`photometric_scale` turns into the squared deflection misfit it stands for.
"""
from __future__ import annotations

import math
import sys
from typing import Optional

import numpy as np
import torch

import nerif.sensing.interpolation as interpolation
from nerif.cache import cached_arrays, content_digest, source_digest
from nerif.sensing.interpolation import Interpolation


def cell_weights(b: int, dtype=torch.float32, device=None) -> tuple[torch.Tensor, torch.Tensor]:
    """Bilinear weights of the ``b x b`` image pixels between the centres of 2 x 2 adjacent rays of a grid binned
    ``b`` times coarser than the image, and those pixels' offsets from the top-left ray's pixel.

    A ray of coarse pixel (row i, column j) sits at the image point ``b j + (b - 1) / 2`` (column; the same for
    rows). The image pixels from that point to the next ray's (exclusive) are at ``ceil(b j + (b - 1) / 2) + k``,
    k < b, a fraction ``(k + o) / b`` of the way, ``o = 1/2`` for even b, 0 for odd b.

    Returns:
        weights (b * b, 4) of the corners (top-left, top-right, bottom-left, bottom-right), pixels row-major;
        offsets (b * b, 2) [px] (column, row) of each pixel from the cell's first pixel (:func:`cell_origin`).
    """
    o = 0.5 if b % 2 == 0 else 0.0
    t = (torch.arange(b, dtype=dtype, device=device) + o) / b
    ty, tx = torch.meshgrid(t, t, indexing="ij")
    tx, ty = tx.reshape(-1), ty.reshape(-1)
    weights = torch.stack([(1 - tx) * (1 - ty), tx * (1 - ty), (1 - tx) * ty, tx * ty], -1)
    k = torch.arange(b, dtype=dtype, device=device)
    ky, kx = torch.meshgrid(k, k, indexing="ij")
    return weights, torch.stack([kx.reshape(-1), ky.reshape(-1)], -1)


def block_pixels(pixel: torch.Tensor, width: int, b: int) -> torch.Tensor:
    """(N,) flat coarse-pixel indices on a grid ``width`` wide (``row * width + column``) -> (N, b * b, 2) the
    image pixels (column, row) of each one's ``b x b`` block, row-major from its top-left pixel."""
    k = torch.arange(b, device=pixel.device)
    ky, kx = torch.meshgrid(k, k, indexing="ij")
    rc = torch.stack([pixel % width, torch.div(pixel, width, rounding_mode="floor")], -1)
    return rc[:, None, :] * b + torch.stack([kx.reshape(-1), ky.reshape(-1)], -1)[None]


def cell_origin(pixel: torch.Tensor, width: int, b: int) -> torch.Tensor:
    """(C,) flat coarse-pixel index of each cell's top-left ray -> (C, 2) the image pixel (column, row) of the
    cell's first image pixel (:func:`cell_weights`): ``ceil(b j + (b - 1) / 2) = b j + ceil((b - 1) / 2)``, the
    top-left pixel of the ray's block (:func:`block_pixels`) moved to the ray's centre."""
    return block_pixels(pixel, width, 1)[:, 0] * b + math.ceil((b - 1) / 2)


def photometric_residual(reference: torch.Tensor, distorted: torch.Tensor, x: torch.Tensor, u: torch.Tensor,
                         read: Interpolation) -> torch.Tensor:
    """``I_ref(x + u) - I_dist(x)`` at integer image pixels ``x`` (P, 2) (column, row) with displacements ``u``
    (P, 2) [px], differentiable in ``u``: ``distorted`` (H, W), ``reference`` the grid ``read`` reads
    (:meth:`~nerif.sensing.interpolation.Interpolation.grid` of the (H, W) reference). Returns (P,)."""
    W = distorted.shape[1]
    xi = x.long()
    observed = distorted.reshape(-1)[xi[:, 1] * W + xi[:, 0]]
    return read.at(reference, x.to(u.dtype) + u) - observed


SCALE_POINTS = 2**18  # points :func:`photometric_scale` averages over, at most


def photometric_scale(reference: torch.Tensor, gain: torch.Tensor, read: Interpolation, step_px: float = 0.05) -> float:
    """What one unit of squared residual is worth in squared deflection units: the mean squared change of the
    reference image per px^2 of displacement, averaged over the two directions, measured as the residual sees it
    (the image shifted ``step_px`` with the same interpolation, from points at random sub-pixel positions:
    differences on the pixel grid underestimate the gradient of a texture a few pixels fine, by 4x at 5 px, and
    the interpolant's gradient is larger at the pixel centres than between them), times ``mean |A|_F^2 / 2``
    (px^2 per squared unit of deflection; ``gain``: (N, 2, 3) the displacement matrices of the view's rays), so
    that the image term's weight is the flow term's. ``reference``: the grid ``read`` reads of an (H, W) image."""
    H, W = (n // read.factor for n in reference.shape)
    g = torch.Generator().manual_seed(0)
    if (H - 5) * (W - 5) <= SCALE_POINTS:  # every pixel, moved off it at random
        rows, cols = torch.meshgrid(torch.arange(2, H - 3, dtype=torch.float64),
                                    torch.arange(2, W - 3, dtype=torch.float64), indexing="ij")
        x = torch.stack([cols.reshape(-1), rows.reshape(-1)], -1) + torch.rand((rows.numel(), 2), generator=g,
                                                                             dtype=torch.float64)
    else:  # a large image: as many random points (the mean to 0.3 %), not a cost that grows with its pixels
        x = torch.rand((SCALE_POINTS, 2), generator=g, dtype=torch.float64) * torch.tensor([W - 5.0, H - 5.0]) + 2
    x = x.to(reference.device)
    ref = reference.double()
    base = read.at(ref, x)
    per_px2 = [float((read.at(ref, x + step_px * x.new_tensor(e)) - base).pow(2).mean()) / step_px**2
               for e in ((1.0, 0.0), (0.0, 1.0))]
    return sum(per_px2) / 2 * float(gain.double().pow(2).sum((-2, -1)).mean()) / 2


def cached_photometric_scale(reference: torch.Tensor, gain: torch.Tensor, read: Interpolation,
                             cache_dir=None) -> float:
    """:func:`photometric_scale`, kept in ``cache_dir`` (None: computed every time) keyed by the grid's and the
    gains' values, the interpolation's class and this code's source and :mod:`nerif.sensing.interpolation`'s: a
    second run on the same images reads it back (1-3 s a capture on 2 cores) and gets the same value to the last
    bit."""
    if cache_dir is None:
        return photometric_scale(reference, gain, read)
    code = source_digest(sys.modules[__name__], interpolation)
    payload = {"reference": content_digest(reference.detach().cpu().numpy()), "read": type(read).__name__,
               "code": code, "gain": content_digest(gain.detach().cpu().numpy())}
    return float(cached_arrays(cache_dir, "scale", payload, lambda: {
        "scale": np.float64(photometric_scale(reference, gain, read))})["scale"])


def bandpass(image: torch.Tensor, highpass_px: Optional[float], lowpass_px: Optional[float] = None) -> torch.Tensor:
    """``image`` blurred by a Gaussian of ``lowpass_px`` [px] (sensor noise: the background's texture is coarser
    than a pixel), less its blur of ``highpass_px`` (a smooth brightness change between the exposures, the flame's
    own light); None or 0 skips either."""
    def blur(img, sigma):
        import kornia

        k = 2 * int(3 * sigma + 0.5) + 1
        return kornia.filters.gaussian_blur2d(img[None, None], (k, k), (sigma, sigma), border_type="reflect")[0, 0]

    image = blur(image, lowpass_px) if lowpass_px else image
    return image - blur(image, highpass_px) if highpass_px else image

