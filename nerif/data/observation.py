"""What one view's camera records of a field: the one place a field's deflections become the pixels of that view's
images, for every consumer that compares a field with the images (the image term, unified BOS, the held-out
image residual): :func:`image_displacement` the forward model, :meth:`ViewObservation.residual` the images' misfit
of a displacement, read by a registered interpolation (:mod:`nerif.sensing.interpolation`).

Units, converted here and nowhere else: deflections in units of sigma (``Scene.observed``'s) or radians; image
displacements in pixels of the full sensor (what the measurement stage reports, ``Scene.displacement_px``) or in
pixels of the view's images (``image px``: the grid its ``ViewImages`` hold, ``binning`` sensor pixels a side).
"""
from __future__ import annotations

from dataclasses import dataclass

import torch

from nerif.losses.images import bandpass, block_pixels, photometric_residual
from nerif.sensing.interpolation import Interpolation


def image_displacement(gain_px: torch.Tensor, eps: torch.Tensor, shake_px: torch.Tensor) -> torch.Tensor:
    """The forward model of a view's images: (..., 2, 3) ``gain_px`` [image px per unit of sigma deflection],
    (..., 3) deflections ``eps`` [sigma] and (..., 2) the camera's shake ``shake_px`` [image px] -> (..., 2) the
    displacement [image px] the distorted image holds against the reference: the field's and the shake. In the
    gain's dtype."""
    return (gain_px * eps.to(gain_px.dtype)[..., None, :]).sum(-1) + shake_px.to(gain_px.dtype)


@dataclass(frozen=True)
class ViewObservation:
    """One view's observation model on the image grid.

    Attributes:
        view: the view's index in its scene. rays: its rays' slice of the scene's.
        pixel: (n,) each ray's flat pixel index on the ray grid, ``width`` wide.
        gain_px: (n, 2, 3) float64: image displacement [image px] per unit of sigma deflection of each ray.
        shake_px: (2,) float64: the camera's rigid shift between the exposures [image px], which the images hold
            and the field does not.
        binning: sensor pixels a side of an image pixel. block: image pixels a ray spans across (``b``), or None
            where the rays are not a whole number of image pixels apart.
        reference, distorted: (H, W) the view's images, intensities in [0, 1].
    """

    view: int
    rays: slice
    pixel: torch.Tensor
    width: int
    gain_px: torch.Tensor
    shake_px: torch.Tensor
    binning: int
    block: int | None
    reference: torch.Tensor
    distorted: torch.Tensor

    def displacement(self, eps: torch.Tensor, rows: torch.Tensor | None = None) -> torch.Tensor:
        """(R, 3) deflections of sigma of the view's rays ``rows`` (indices among its own rays; default: all) ->
        (R, 2) the displacements [image px] its distorted image holds against its reference there: the field's,
        and the camera's shake."""
        return image_displacement(self.gain_px if rows is None else self.gain_px[rows], eps, self.shake_px)

    def image_px(self, u_sensor_px: torch.Tensor) -> torch.Tensor:
        """(..., 2) displacements [px of the full sensor] -> [image px]."""
        return u_sensor_px / self.binning

    def sensor_px(self, u_image_px: torch.Tensor) -> torch.Tensor:
        """(..., 2) displacements [image px] -> [px of the full sensor]."""
        return u_image_px * self.binning

    def pixels(self, pixel: torch.Tensor | None = None) -> torch.Tensor:
        """(n, b^2, 2) the image pixels (column, row) of the blocks of rays ``pixel`` (their flat ray-grid indices;
        default: every ray of the view), row-major from each block's top-left pixel."""
        return block_pixels(self.pixel if pixel is None else pixel, self.width, self.block)

    def images(self, read: Interpolation, highpass_px: float | None = None,
               lowpass_px: float | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The view's images as a residual compares them (float64): the reference's grid ``read`` reads
        (:meth:`~nerif.sensing.interpolation.Interpolation.grid`) and the (H, W) distorted image, both band-passed
        first where ``highpass_px`` or ``lowpass_px`` [image px] is set (:func:`~nerif.losses.images.bandpass`)."""
        ref, dist = (bandpass(i.double(), highpass_px, lowpass_px) for i in (self.reference, self.distorted))
        return read.grid(ref), dist

    def residual(self, u: torch.Tensor, read: Interpolation, images: tuple[torch.Tensor, torch.Tensor],
                 pixel: torch.Tensor | None = None) -> torch.Tensor:
        """(n, 2) displacements [image px] of the rays ``pixel`` (flat ray-grid indices; default: every ray of the
        view), one for each ray's block of image pixels -> (n, b^2) ``I_ref(x + u) - I_dist(x)`` at those pixels
        (sensor noise where ``u`` is right), the reference read by ``read`` from ``images`` (:meth:`images`)."""
        x = self.pixels(pixel)  # (n, b^2, 2)
        grid, dist = images
        r = photometric_residual(grid, dist, x.reshape(-1, 2), u[:, None, :].expand(-1, x.shape[1], -1).reshape(-1, 2),
                                 read)
        return r.reshape(x.shape[:2])


def observations(scene) -> list[ViewObservation]:
    """Each view's :class:`ViewObservation` of ``scene`` (a :class:`nerif.data.scene.Scene` with images)."""
    if scene.images is None:
        raise ValueError("an observation model on the image grid needs the views' background images")
    b, shakes, out = scene.image_block(), scene.shake_px(), []
    for v, (cam, im) in enumerate(zip(scene.cameras, scene.images)):
        sl = scene.view_slice(v)
        out.append(ViewObservation(v, sl, scene.pixel[sl], cam.width,
                                   scene.gain[sl] * (scene.scale / im.camera.binning), shakes[v] / im.camera.binning,
                                   im.camera.binning, b, im.reference, im.distorted))
    return out
