"""A sampled image read between its pixels: how the image term models the background a displaced ray sees.

A camera's image of a background is a sampled, band-limited picture: the lens and the pixel's area blur the
texture before the sensor samples it, so its pixels determine the picture between them (Shannon). An interpolant
that is not the band-limited one reads it with a bias that depends on the texture: on the shared captures' textures
(wavelengths of 3-12 px) the cubic B-spline's photometric optimum lies at 1.01-1.04x the true displacements, PyTorch's
bicubic convolution's at 0.92-1.00x (``benchmarks/image_model.py``), and a field fitted to such images turns a gain
of 2 % into 10-15 % of error. ``bandlimited`` reads the picture itself.

Each interpolation is registered by name (:data:`INTERPOLATIONS`, ``data_term.interpolation``) and does two things:
:meth:`Interpolation.grid` turns an image (H, W) into the grid it reads, ``factor`` times finer along each axis (its
samples at ``(j + 1/2) / factor - 1/2`` image px), and :meth:`Interpolation.at` reads that grid at image points
(P, 2) [px] (column, row; pixel centres at integers), differentiably in the points. Grids of several images stacked
row-wise with ``factor * m`` rows of padding between them read as the images stacked with ``m``.
"""
from __future__ import annotations

import numpy as np
import torch
from scipy import fft, ndimage

from nerif.registry import Registry

INTERPOLATIONS = Registry("interpolation")


def sample(image: torch.Tensor, x: torch.Tensor, mode: str = "bicubic") -> torch.Tensor:
    """The image at points ``x`` (P, 2) [px] (column, row; pixel centres at integers), differentiable in ``x``:
    (H, W) -> (P,). Points past the border read the border value. ``mode``: ``bilinear``, ``bicubic`` (PyTorch's
    cubic convolution, a = -0.75) or ``bspline`` (the cubic B-spline, ``image`` then holding its coefficients,
    :func:`bspline_coefficients`): on a texture of 3-9 px wavelengths shifted 0.3 px, their model errors are 50 %,
    13 % and 6.5 % of the change the shift makes (``tests/test_interpolation.py``)."""
    if mode == "bspline":
        return _bspline(image, x)
    H, W = image.shape
    scale = x.new_tensor([2.0 / max(W - 1, 1), 2.0 / max(H - 1, 1)])
    grid = (x * scale - 1.0).to(image.dtype)[None, None]  # (1, 1, P, 2), align_corners=True
    out = torch.nn.functional.grid_sample(image[None, None], grid, mode=mode, padding_mode="border",
                                          align_corners=True)
    return out[0, 0, 0]


def _mirrored(i: torch.Tensor, n: int) -> torch.Tensor:
    """Indices reflected about the first and last pixel (scipy's ``mirror``: -1 -> 1, n -> n - 2), then clamped."""
    i = torch.where(i < 0, -i, i)
    return torch.where(i > n - 1, 2 * (n - 1) - i, i).clamp(0, n - 1)


def bspline_coefficients(image: torch.Tensor) -> torch.Tensor:
    """(H, W) -> (H, W) the coefficients of the cubic B-spline through ``image``'s pixel values (mirror boundary;
    ``scipy.ndimage.spline_filter``), what :func:`sample` reads with ``mode="bspline"``."""
    c = ndimage.spline_filter(image.detach().cpu().double().numpy(), order=3, mode="mirror")
    return torch.as_tensor(c, dtype=image.dtype, device=image.device)


def _bspline(coefficients: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
    """The cubic B-spline of ``coefficients`` (H, W) at ``x`` (P, 2) [px] (column, row): the 4 x 4 coefficients
    around each point, weighted by the B-spline's basis; past the border the coefficients mirror about the edge
    pixel, as :func:`bspline_coefficients` assumed them (then clamped: far outside reads the border's)."""
    H, W = coefficients.shape
    whole = torch.floor(x)
    t = (x - whole).to(coefficients.dtype)
    t2, t3 = t * t, t * t * t
    w = torch.stack([(1 - t) ** 3, 3 * t3 - 6 * t2 + 4, -3 * t3 + 3 * t2 + 3 * t + 1, t3], -1) / 6  # (P, 2, 4)
    k = torch.arange(-1, 3, device=x.device)
    cols, rows = (_mirrored(whole[:, a:a + 1].long() + k, n) for a, n in ((0, W), (1, H)))
    near = coefficients.reshape(-1)[rows[:, :, None] * W + cols[:, None, :]]  # (P, 4 rows, 4 columns)
    return torch.einsum("pr,pc,prc->p", w[:, 1], w[:, 0], near)


def bandlimited_upsampled(image: torch.Tensor, factor: int) -> torch.Tensor:
    """(H, W) -> (factor H, factor W) the band-limited picture through ``image``'s pixels, sampled ``factor`` times
    finer: its cosine series (the image mirrored about its borders, so no edge rings) evaluated at
    ``(j + 1/2) / factor - 1/2`` px. Each pixel value is kept where a sample falls on it (odd ``factor``)."""
    if factor == 1:
        return image
    H, W = image.shape
    c = fft.dctn(image.detach().cpu().double().numpy(), type=2, workers=-1)
    padded = np.zeros((factor * H, factor * W))
    padded[:H, :W] = c
    fine = fft.idctn(padded, type=2, workers=-1) * factor**2
    return torch.as_tensor(fine, dtype=image.dtype, device=image.device)


class Interpolation:
    """How an image is read between its pixels: :meth:`grid` once per image, :meth:`at` at every step.

    Attributes:
        factor: samples of the grid per image pixel along each axis.
    """

    factor = 1

    def grid(self, image: torch.Tensor) -> torch.Tensor:
        """(H, W) -> (factor H, factor W) what :meth:`at` reads."""
        return image

    def at(self, grid: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """The image at points ``x`` (P, 2) [image px] (column, row) from its :meth:`grid` -> (P,)."""
        raise NotImplementedError

    def on_grid(self, x: torch.Tensor) -> torch.Tensor:
        """Image points (..., 2) [px] -> the same points in the grid's samples."""
        f = self.factor
        return x if f == 1 else f * (x + 0.5) - 0.5

    def __call__(self, image: torch.Tensor, x: torch.Tensor) -> torch.Tensor:
        """``image`` (H, W) at ``x`` (P, 2) [px], its grid made on the way (for a single reading)."""
        return self.at(self.grid(image), x)


@INTERPOLATIONS.register("bilinear")
class Bilinear(Interpolation):
    """Linear in each axis between the 2 x 2 pixels around a point (the model error of a 0.3 px shift on a 3-9 px
    texture: 50 % of the change it makes)."""

    def at(self, grid, x):
        return sample(grid, x, "bilinear")


@INTERPOLATIONS.register("bicubic")
class Bicubic(Interpolation):
    """PyTorch's cubic convolution (a = -0.75) over the 4 x 4 pixels around a point: not an exact interpolant of a
    band-limited picture; its optimum lies at 0.92-1.00x the true displacements (13 % model error at 0.3 px)."""

    def at(self, grid, x):
        return sample(grid, x, "bicubic")


@INTERPOLATIONS.register("bspline")
class BSpline(Interpolation):
    """The cubic B-spline through the pixels (6.5 % model error at 0.3 px); between pixels it smooths the sensor
    noise more than at them, which draws the fit towards half-pixel positions: its optimum lies at 1.01-1.04x the
    true displacements on noisy 3-12 px textures."""

    def grid(self, image):
        return bspline_coefficients(image)

    def at(self, grid, x):
        return _bspline(grid, x)


@INTERPOLATIONS.register("bandlimited")
class BandLimited(BSpline):
    """The band-limited picture through the pixels (:func:`bandlimited_upsampled`), kept on a grid ``factor``
    times finer and read there by its cubic B-spline: on that grid even a 3 px wavelength spans 6 samples, where the
    spline's error is below 0.1 % of the gain. Its optimum lies at 1.000 +- 0.005x the true displacements on the
    shared captures' textures; it reads the sensor noise of the reference as it is (the same variance everywhere),
    so its residual at the truth is 1-3 % larger than the B-spline's, with no bias. Memory: ``factor^2`` floats a
    pixel."""

    factor = 2

    def grid(self, image):
        return bspline_coefficients(bandlimited_upsampled(image, self.factor))

    def at(self, grid, x):
        return _bspline(grid, self.on_grid(x))


def interpolation(name: str) -> Interpolation:
    """The registered interpolation ``name`` (``bilinear``, ``bicubic``, ``bspline``, ``bandlimited``)."""
    return INTERPOLATIONS.get(name)()
