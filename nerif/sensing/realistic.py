"""Realistic BOS sensing of a synthetic field: what a camera rig really measures.

Per view: finite-aperture rendering of the deflections (``aperture_rays`` rays per pixel from points across
the lens to the background point the pixel is focused on, averaged: the probe is seen blurred by the circle
of confusion), conversion to image displacements, a seeded background pattern blurred by diffraction and seen
through them as a camera's pixels integrate it (``pixel_samples`` points a pixel and axis, each displaced; 1: the
pattern sampled at pixel centres and warped by bicubic interpolation, much as the image term models a view, then
blurred), sensor noise on the distorted and the reference image, then the measurement stage a capture goes through
(:func:`nerif.sensing.measurement.measure_view`: the optical flow, block means to the training grid, validity), and
the estimated displacements converted back to world-frame deflections on the training rays.

Three pixel grids, all of the same sensor: the *image* grid (``image_binning``, 1 = full sensor) on which
patterns, warping and flow happen; the *render* grid (``render_binning``) on which the aperture-averaged
deflections are traced and then interpolated to the image grid; the *training* grid (the rig's binning) that
receives block means of the estimated displacements.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from nerif.cache import cached_arrays
from nerif.geometry import Camera, ProbeBox, outside_the_box
from nerif.renderers.voxel import voxel_deflection
from nerif.sensing.burner import DARK, burner_pixels
from nerif.sensing.displacement import deflection_to_displacement
from nerif.sensing.emission import flame_light
from nerif.sensing.flow import FLOW, check_flow
from nerif.sensing.measurement import MEASUREMENT
from nerif.export import to_uint8
from nerif.sensing.imaging import add_noise, diffraction_blur, expose, resample, warp
from nerif.sensing.models import SENSING
from nerif.sensing.optics import aperture_points, aperture_rays, circle_of_confusion
from nerif.sensing.patterns import PATTERNS
from nerif.sensing.record import chain_records

log = logging.getLogger(__name__)


def aperture_deflection(delta: torch.Tensor, box: ProbeBox, camera: Camera, dirs: torch.Tensor, n_rays: int,
                        step_mm: Optional[float] = None, chunk_pixels: int = 4096) -> torch.Tensor:
    """Deflections seen by pixels of a finite-aperture camera focused on the background.

    Args:
        delta: (nx, ny, nz) field on ``box``. dirs: (P, 3) chief-ray directions of the pixels.
        n_rays: rays per pixel across the aperture (1 = the pinhole chief ray).
    Returns:
        (P, 3) mean deflection [rad] over each pixel's aperture rays.
    """
    out = []
    for i in range(0, len(dirs), chunk_pixels):
        o, d = aperture_rays(camera, dirs[i:i + chunk_pixels], n_rays)
        o, d = o.reshape(-1, 3).to(delta.dtype), d.reshape(-1, 3).to(delta.dtype)
        hit = box.intersect(o, d)[2]
        eps = delta.new_zeros(len(o), 3)
        if hit.any():
            eps[hit] = voxel_deflection(delta, box, o[hit], d[hit], step_mm)
        out.append(eps.reshape(-1, n_rays, 3).mean(1))
    return torch.cat(out) if out else delta.new_zeros(0, 3)


def true_displacements(delta: torch.Tensor, box: ProbeBox, render_camera: Camera, image_camera: Camera,
                       dirs: torch.Tensor, n_rays: int, step_mm: float, cache_dir, field_key: str) -> np.ndarray:
    """(h, w, 2) float32 displacements [px of ``image_camera``'s images] of the aperture-averaged deflections
    (:func:`aperture_deflection`) on ``render_camera``'s grid (``dirs`` (h w, 3) its chief rays), cached by the
    field (``field_key``), the box, the step, the aperture rays and every attribute of the camera."""
    eps = cached_arrays(cache_dir, "aperture", {
        "delta": field_key, "box": [box.shape, box.voxel_mm], "step": step_mm, "rays": n_rays,
        "camera": render_camera.fingerprint()},
        lambda: {"eps": aperture_deflection(delta, box, render_camera, dirs, n_rays, step_mm).cpu().numpy()})["eps"]
    eps = torch.as_tensor(eps, dtype=torch.float64, device=dirs.device)  # the cache gives it back on the CPU
    u = deflection_to_displacement(eps, dirs, image_camera).cpu().numpy().astype(np.float32)
    return u.reshape(render_camera.height, render_camera.width, 2)


def exposures(background: torch.Tensor, u: torch.Tensor, blur_px: float, noise_variance: float, gain_drift: float,
              glow: Optional[np.ndarray], generator: torch.Generator, gain_ramp: float = 0.0,
              hidden: Optional[np.ndarray] = None, samples: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The reference and the distorted exposure of one view.

    Args:
        background: (H s, W s) the pattern, intensities in [0, 1], sampled ``s = samples`` times a pixel and axis:
            more than 1, each pixel integrates it (:func:`nerif.sensing.imaging.expose`); 1, the pattern at the
            displaced pixel centres, interpolated bicubically (:func:`nerif.sensing.imaging.warp`).
        u: (H, W, 2) displacements [px of these images].
        blur_px: the diffraction spot's diameter [px]: with ``samples`` above 1 the lens blurs the background before
            the pixels integrate it, as a camera's optics do (:func:`nerif.sensing.imaging.diffraction_blur` on the
            fine grid; the displacements vary little over the spot); with 1, the sampled image is blurred (the
            chain of before issue 56, whose images keep the aliasing a lens removes).
        noise_variance: of the additive Gaussian noise on each.
        gain_drift: the distorted exposure's brightness over the reference's, less 1; ``gain_ramp``: that gain
            grows by this much more from the left edge to the right (an uneven illumination drift).
        glow: (H, W) the flame's own light on the distorted exposure, as a fraction of the background's mean
            brightness, or None.
        hidden: (H, W) bool, pixels that see an opaque occluder (:data:`nerif.sensing.burner.DARK`, no texture) in
            both exposures, or None.
    Returns: (H, W) reference and distorted images (floats, noise drawn from ``generator``: reference first), clipped
    to [0, 1] as a sensor clips at its full scale.
    """
    if samples > 1:
        background = diffraction_blur(background, blur_px * samples)  # the lens, then the pixels
        reference, seen = expose(background, None, samples), expose(background, u, samples)
    else:
        reference, seen = (diffraction_blur(x, blur_px) for x in (background, warp(background, u)))
    gain = (1.0 + gain_drift) * (1.0 + gain_ramp * torch.linspace(0.0, 1.0, u.shape[1]))[None, :]
    distorted = seen * gain
    if hidden is not None:
        occluder = torch.as_tensor(hidden)
        reference, distorted = (torch.where(occluder, DARK, x) for x in (reference, distorted))
    if glow is not None:
        distorted = distorted + float(background.mean()) * torch.as_tensor(glow)
    return tuple(np.clip(add_noise(x, noise_variance, generator).numpy(), 0.0, 1.0) for x in (reference, distorted))


@dataclass(frozen=True)
class Sensor:
    """The settings of the realistic chain that shape each view's two exposures (``data.sensor``; each as
    :func:`realistic` documents it), checked before the long work by :meth:`check`."""

    aperture_rays: int
    wavelength_um: float
    noise_variance: float
    image_binning: int
    render_binning: int
    seed: int
    luminosity: float
    gain_drift: float
    gain_ramp: float
    shake_px: float
    burner_radius_mm: float
    burner_top_mm: Optional[float]
    pixel_samples: int

    def check(self, camera: Camera, rig_binning: int, pattern: dict, flow: dict) -> None:
        """One sentence for a setting that cannot run (``camera``: a training camera; ``pattern``, ``flow``: the
        configs the chain builds)."""
        PATTERNS.get(pattern["name"]), FLOW.get(flow["name"])
        check_flow(flow)  # settings that cannot measure say so here, not as an empty view each after the rendering
        if self.noise_variance < 0:
            raise ValueError(f"noise variance must be >= 0, got {self.noise_variance}")
        if not self.luminosity >= 0 or not self.gain_drift > -1 or not self.gain_ramp > -1 or \
                not self.shake_px >= 0 or not self.burner_radius_mm >= 0:
            raise ValueError(f"data.sensor.luminosity={self.luminosity}, data.sensor.shake_px={self.shake_px} and "
                             f"data.sensor.burner_radius_mm={self.burner_radius_mm} must be at least 0, "
                             f"data.sensor.gain_drift={self.gain_drift} and data.sensor.gain_ramp={self.gain_ramp} "
                             "above -1")
        if not (isinstance(self.pixel_samples, int) and 1 <= self.pixel_samples <= 16):
            raise ValueError(f"data.sensor.pixel_samples={self.pixel_samples} must be a whole number from 1 to 16")
        aperture_points(self.aperture_rays, 1.0)
        for b, what in ((self.image_binning, "image_binning"), (self.render_binning, "render_binning")):
            if b < 1 or rig_binning % b and b % rig_binning:
                raise ValueError(f"data.sensor.{what}={b} must divide or be a multiple of the rig's binning "
                                 f"{rig_binning}")
            camera.unbinned(rig_binning).binned(b)

    def expose(self, delta: torch.Tensor, box: ProbeBox, cam: Camera, rig_binning: int, pattern: dict, v: int,
               step_mm: float, cache_dir, field_key: str) -> dict:
        """View ``v`` (camera ``cam``, of the rig's binning) of the field ``delta`` on ``box``: ``u_ren`` (h, w, 2)
        the true displacements on the render grid [px of the images], ``reference`` and ``distorted`` (H, W) its two
        exposures on the image grid, ``coc_px`` the circle of confusion [px of the images], ``shake`` (2,) [px of the
        full sensor], ``occluded`` (the share of the ray grid's blocks that see some of the burner tube, or None)."""
        img_cam = cam.unbinned(rig_binning).binned(self.image_binning)
        ren_cam = cam.unbinned(rig_binning).binned(self.render_binning)
        H, W = img_cam.height, img_cam.width
        d_ren = ren_cam.pixel_directions(torch.float64).to(delta.device)
        u_ren = true_displacements(delta, box, ren_cam, img_cam, d_ren, self.aperture_rays, step_mm, cache_dir,
                                   field_key)
        coc = circle_of_confusion(img_cam, self.wavelength_um)
        glow = self.luminosity * flame_light(delta, box, img_cam, coc["d_mm"] / img_cam.pitch_mm, step_mm) \
            if self.luminosity > 0 else None
        top_mm = -0.5 * float(box.extent_mm[1]) if self.burner_top_mm is None else float(self.burner_top_mm)
        tube = burner_pixels(img_cam, self.burner_radius_mm, top_mm) if self.burner_radius_mm > 0 else None
        background = torch.as_tensor(PATTERNS.build(pattern, height=H, width=W, seed=self.seed * 1009 + v,
                                                     samples=self.pixel_samples))
        shake = np.random.default_rng(self.seed * 7919 + v).normal(0.0, self.shake_px, 2)  # px of the full sensor
        u_img = torch.as_tensor(resample(u_ren, H, W) + (shake / self.image_binning).astype(np.float32))
        reference, distorted = exposures(background, u_img, coc["d_diff_mm"] / img_cam.pitch_mm, self.noise_variance,
                                         self.gain_drift, glow, torch.Generator().manual_seed(self.seed * 1009 + v),
                                         self.gain_ramp, tube, self.pixel_samples)
        occluded = None
        if tube is not None:  # the share of the ray grid's blocks that see some of the tube
            occluded = np.float64((resample(tube.astype(np.float32), cam.height, cam.width) > 0).mean())
        return dict(u_ren=u_ren, reference=reference, distorted=distorted, coc_px=coc["d_mm"] / img_cam.pitch_mm,
                    shake=shake, occluded=occluded)


def _view_record(x: dict, m, cam: Camera, pixel: torch.Tensor, image_binning: int) -> tuple[dict, np.ndarray]:
    """One view's fields of the chain's records (:func:`nerif.sensing.record.chain_records`) from what the chain
    made (``x``, :meth:`Sensor.expose`) and measured (``m``, a :class:`nerif.sensing.measurement.ViewMeasurement`)
    on the ray grid of ``cam``, and the squared errors (n, 2) of the measured displacements at the training rays' ``pixel`` [px^2 of the images]."""
    pix = pixel.cpu().numpy()
    u_true = resample(x["u_ren"], cam.height, cam.width)
    u_est = m.displacement / np.float32(image_binning)  # the figures' unit: px of the images' grid
    err = (u_est.reshape(-1, 2)[pix] - u_true.reshape(-1, 2)[pix]) ** 2
    return dict(displacement_px=m.displacement, valid=m.valid, left_out=m.left_out,
                reference=to_uint8(x["reference"]), distorted=to_uint8(x["distorted"]),
                u_true=u_true.astype(np.float32),
                circle_of_confusion_px=np.float64(x["coc_px"]), shake_true_px=x["shake"],
                occluded_true=x["occluded"], found=m.found.report()), err[np.isfinite(err).all(-1)]


@SENSING.register("realistic")
def realistic(delta: torch.Tensor, box: ProbeBox, cameras: list[Camera], dirs: torch.Tensor, pixel: torch.Tensor,
              view_start: torch.Tensor, step_mm: Optional[float], rig_binning: int, pattern: dict, flow: dict,
              aperture_rays: int = 60, wavelength_um: float = 0.5, noise_variance: float = 0.0,
              image_binning: int = 1, render_binning: Optional[int] = None, seed: int = 0, luminosity: float = 0.0,
              gain_drift: float = 0.0, gain_ramp: float = 0.0, shake_px: float = 0.0, burner_radius_mm: float = 0.0,
              burner_top_mm: Optional[float] = None, pixel_samples: int = 4, measure: Optional[dict] = None,
              cache_dir=None):
    """Observed deflections of the training rays through the realistic BOS chain.

    Args:
        delta: (nx, ny, nz) true field on ``box`` (rendered from it). cameras: the training cameras.
        dirs, pixel, view_start: the training rays (see :class:`nerif.data.scene.Scene`).
        pattern, flow, measure: configs of a :data:`PATTERNS`, a :data:`FLOW` and a
            :data:`nerif.sensing.measurement.MEASUREMENT` entry (None: the default stage).
        noise_variance: variance of the additive Gaussian noise on each image (intensities in [0, 1]).
        luminosity: the flame's own light added to the distorted image, at its brightest this fraction of the
            background's mean brightness, shaped like the flame's projection and seen out of focus
            (:func:`nerif.sensing.emission.flame_light`: blurred by the circle of confusion at the probe). Where
            light and background exceed the full scale, the image clips (saturates), as a sensor does.
        gain_drift: the distorted exposure's brightness over the reference's, less 1 (illumination drift):
            0.1 = 10 % brighter. gain_ramp: that gain grows by this much more across the image, left to right.
        shake_px: camera vibration between the exposures: each view's distorted image moved by a random shift,
            this RMS per axis [px of the full sensor], drawn with ``seed`` (the record's ``shake_true_px``).
        burner_radius_mm, burner_top_mm: an opaque burner tube on the axis (:mod:`nerif.sensing.burner`), its top
            at ``y = burner_top_mm`` (None: the probe box's bottom face); radius 0: none. The record's
            ``occluded_true`` is the share of each view's ray grid it hides.
        pixel_samples: points a pixel and axis at which the background is seen, each through its own interpolated
            displacement, and averaged: the pixel's integration of the light (1: the pattern sampled at pixel
            centres and warped bicubically, as the image term interpolates: nearly an inverse crime for it).
        step_mm: quadrature step of the aperture rays (default: one voxel of ``delta``; the aperture average
            is as accurate with it as with half a voxel, to 2e-5 on Phantom 5, at half the cost).
        cache_dir: where the aperture renderings (the costly part) are cached, keyed by the field and the
            optics, so that sweeps over noise, pattern or flow reuse them.
    Returns:
        what the views recorded and measured (:class:`nerif.sensing.record.MeasuredViews`: the observations are the
        measured displacements, which the scene turns into deflections as it does a capture's,
        :func:`nerif.data.scene.scene_from_displacements`) and what only the chain knows
        (:class:`nerif.sensing.record.SensingRecord`: its truth).
    """
    sensor = Sensor(aperture_rays, wavelength_um, noise_variance, image_binning, render_binning or rig_binning,
                    seed, luminosity, gain_drift, gain_ramp, shake_px, burner_radius_mm, burner_top_mm, pixel_samples)
    measure = dict(measure or {"name": "default"})
    MEASUREMENT.get(measure["name"])
    sensor.check(cameras[0], rig_binning, pattern, flow)  # before the long work
    step_mm = step_mm or box.voxel_mm
    field_key = hashlib.sha256(delta.cpu().numpy().tobytes()).hexdigest()
    per_view = []  # each view's fields of the record
    quiet = outside_the_box(cameras, pixel, view_start)  # pixels whose ray misses the box
    sq_err, count = 0.0, 0
    for v, cam in enumerate(cameras):
        x = sensor.expose(delta, box, cam, rig_binning, pattern, v, step_mm, cache_dir, field_key)
        m = MEASUREMENT.build(measure, distorted=x["distorted"], reference=x["reference"], flow=flow,
                              grid_px=(cam.height, cam.width), image_binning=image_binning,
                              quiet=quiet[v], name=cam.name)
        record, err = _view_record(x, m, cam, pixel[int(view_start[v]):int(view_start[v + 1])], image_binning)
        per_view.append(record)
        sq_err, count = sq_err + float(err.sum()), count + len(err)
        log.info("%s: true displacement up to %.2f px, circle of confusion %.1f px", cam.name,
                 float(np.abs(x["u_ren"]).max()), x["coc_px"])
    return chain_records(per_view, np.sqrt(sq_err / max(count, 1)))
