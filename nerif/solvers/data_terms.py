"""What the neural field is fitted to (``data_term=``): the deflections the optical flow measured (``flow``), or
the background images themselves (``images``).

A data term draws each iteration's rays (:meth:`draw` -> :class:`RayBatch`) and, given the deflections the
field renders along them (operator name -> (R, 3) sigma units), returns the misfit per operator
(:meth:`terms`), in the unit of a squared deflection of sigma for both, so that the other loss weights mean the
same whichever term is fitted.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Optional

import torch

from nerif.data import Scene
from nerif.losses import deflection_terms
from nerif.losses.images import cell_origin, cell_weights, highpass, photometric_residual, photometric_scale
from nerif.registry import Registry
from nerif.sensing.displacement import displacement_matrix
from nerif.solvers.batches import RayBatcher

log = logging.getLogger(__name__)
DATA_TERMS = Registry("data term", package="nerif.solvers")


@dataclass
class RayBatch:
    """The rays of one training step: ``origins``, ``dirs`` (R, 3) and ``index`` (R,) their scene indices."""

    origins: torch.Tensor
    dirs: torch.Tensor
    index: torch.Tensor


def scene_rays(scene: Scene, index: torch.Tensor) -> RayBatch:
    views = torch.searchsorted(scene.view_start, index, right=True) - 1
    return RayBatch(scene.origins[views], scene.dirs[index], index)


@DATA_TERMS.register("flow")
class DeflectionTerm:
    """``mean |eps - eps_obs|^2`` over random rays, ``eps_obs`` the scene's observed deflections (the optical
    flow's displacements converted through the rig, or a synthetic scene's own)."""

    def setup(self, scene: Scene, batches: RayBatcher, iterations: int, masks=None) -> "DeflectionTerm":
        self.scene, self.batches = scene, batches
        return self

    def draw(self, iteration: int) -> RayBatch:
        return scene_rays(self.scene, self.batches(iteration))

    def terms(self, eps: dict, batch: RayBatch, iteration: int) -> dict:
        return deflection_terms(eps, self.scene.observed[batch.index])


@DATA_TERMS.register("images")
class ImageTerm:
    """The photometric residual ``I_ref(x + u(x)) - I_dist(x)`` at every image pixel of random cells of the ray
    grid: the field's deflections are rendered at the 2 x 2 rays around a cell, turned into displacements [image
    px] through the rig geometry, interpolated bilinearly to the cell's ``b x b`` image pixels (``b``: rays are
    ``b`` image pixels apart), and the reference image is sampled there (bicubic). No optical flow enters it,
    except for the first ``flow_warmup`` share of the iterations, which fit the flow's deflections to start
    from (the residual is not convex beyond about half the background's texture wavelength).

    Args:
        flow_warmup: share of the iterations that fit the flow term first (0: images from the start).
        highpass_px: compare the images less their Gaussian blur of this width [px] (a smooth brightness
            change between the exposures, the flame's own light); null: as they are.
        interpolation: of the reference image: ``bicubic`` or ``bilinear``.
    """

    def __init__(self, flow_warmup: float = 0.25, highpass_px: Optional[float] = 8.0, interpolation: str = "bicubic"):
        if not 0.0 <= flow_warmup < 1.0:
            raise ValueError(f"data_term.flow_warmup={flow_warmup}: a share of the iterations within [0, 1)")
        if highpass_px is not None and not highpass_px >= 0:
            raise ValueError(f"data_term.highpass_px={highpass_px}: a width in pixels (or null)")
        if interpolation not in ("bicubic", "bilinear"):
            raise ValueError(f"data_term.interpolation must be bicubic or bilinear, got '{interpolation}'")
        self.flow_warmup, self.highpass_px, self.mode = float(flow_warmup), highpass_px, interpolation
        self.flow = DeflectionTerm()

    def setup(self, scene: Scene, batches: RayBatcher, iterations: int, masks=None) -> "ImageTerm":
        """The cells of every view, the displacement matrices of every ray, the images to compare; ``batches``
        is the flow term's (its settings and random stream are this term's too)."""
        if scene.images is None:
            raise ValueError("data_term=images needs the background images, which these data do not have: use "
                             "data=capture or data.sensing=realistic, or data_term=flow")
        self.scene, self.flow_iterations = scene, int(round(self.flow_warmup * iterations))
        self.flow.setup(scene, batches, iterations)
        device = scene.dirs.device
        self.b, self.images, self.gain, self.scale = [], [], [], []
        corner = torch.full((len(scene.dirs), 3), -1, dtype=torch.long, device=device)
        for v, (cam, im) in enumerate(zip(scene.cameras, scene.images)):
            b = cam.binning // im.camera.binning
            if b * im.camera.binning != cam.binning or b < 2:
                raise ValueError(f"{cam.name}: data_term=images needs rays at least 2 image pixels apart, a whole "
                                 f"number of them (rays binned {cam.binning}, images {im.camera.binning}): raise the "
                                 "binning (data.binning or rig.binning)")
            sl = scene.view_slice(v)
            pixel = scene.pixel[sl]
            lut = torch.full((cam.height * cam.width,), -1, dtype=torch.long, device=device)
            lut[pixel] = torch.arange(sl.start, sl.stop, device=device)
            col, row = pixel % cam.width, torch.div(pixel, cam.width, rounding_mode="floor")
            for k, (dc, dr) in enumerate(((1, 0), (0, 1), (1, 1))):  # right, down, diagonal neighbours
                inside = (col + dc < cam.width) & (row + dr < cam.height)
                corner[sl][inside, k] = lut[(pixel + dr * cam.width + dc)[inside]]
            A = displacement_matrix(scene.dirs[sl].double(), im.camera) * scene.scale  # px per unit of sigma
            ref = highpass(im.reference, self.highpass_px)
            self.b.append(b)
            self.images.append((ref, highpass(im.distorted, self.highpass_px)))
            self.gain.append(A.float())
            self.scale.append(photometric_scale(ref, A))
        self.corner = corner
        allowed = (corner >= 0).all(-1)
        self.batches = RayBatcher(scene, masks.inside if masks is not None else None, batches.rays_per_batch // 4,
                                  batches.views_per_batch, batches.outside_fraction, batches.generator, allowed)
        self.offsets = [scene.view_start[v] for v in range(scene.n_views)]
        return self

    def draw(self, iteration: int) -> RayBatch:
        if iteration < self.flow_iterations:
            return self.flow.draw(iteration)
        top_left = self.batches(iteration)
        return scene_rays(self.scene, torch.cat([top_left[:, None], self.corner[top_left]], 1).reshape(-1))

    def terms(self, eps: dict, batch: RayBatch, iteration: int) -> dict:
        if iteration < self.flow_iterations:
            return self.flow.terms(eps, batch, iteration)
        s = self.scene
        cells = batch.index.reshape(-1, 4)
        views = torch.searchsorted(s.view_start, cells[:, 0].contiguous(), right=True) - 1
        out = {}
        for name, e in eps.items():
            e = e.reshape(-1, 4, 3)
            total = e.new_zeros(())
            for v in views.unique().tolist():
                sel = views == v
                c = cells[sel]
                A = self.gain[v][c - self.offsets[v]]  # (C, 4, 2, 3)
                u = (A @ e[sel][..., None])[..., 0]  # (C, 4, 2) [image px]
                weights, offsets = cell_weights(self.b[v], u.dtype, u.device)
                u = torch.einsum("pk,ckd->cpd", weights, u)  # (C, b^2, 2)
                x = cell_origin(s.pixel[c[:, 0]], s.cameras[v].width, self.b[v])[:, None, :] + offsets
                r = photometric_residual(*self.images[v], x.reshape(-1, 2), u.reshape(-1, 2), self.mode)
                total = total + (r**2).sum() / (self.scale[v] * weights.shape[0])
            out[name] = total / len(cells)
        return out
