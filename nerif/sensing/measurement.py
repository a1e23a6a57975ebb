"""The measurement stage of one view: its distorted and reference background images in; the displacements on the
ray grid, their validity per pixel and what was found out. A capture (:mod:`nerif.data.capture`) and the
realistic chain (:mod:`nerif.sensing.realistic`) both measure through it, so that every synthetic benchmark runs
each step a real capture goes through. It is the one place the optical flow (:data:`nerif.sensing.flow.FLOW`)
runs; every step a view's images need before reconstruction belongs here, one module a step:
:mod:`~nerif.sensing.saturation` and :mod:`~nerif.sensing.occlusion` (pixels with no readable background),
the flow, :mod:`~nerif.sensing.shake` (the camera's rigid motion between the exposures, taken off) and
:mod:`~nerif.sensing.vectors` (outliers). Stages are registered in :data:`MEASUREMENT` (config group
``measure``).
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from nerif.cache import cached_arrays, content_digest
from nerif.registry import Registry
from nerif.sensing.findings import Findings
from nerif.sensing.flame_light import without_flame_light
from nerif.sensing.flow import estimate
from nerif.sensing.imaging import enlarged, resample, shrunk
from nerif.sensing.noise import MIN_PIXELS, residual_noise
from nerif.sensing.occlusion import local_contrast, occluded
from nerif.sensing.saturation import TOP, saturated
from nerif.sensing.shake import MIN_QUIET, photometric_shift, rigid_shift
from nerif.sensing.texture import shrink_factor, texture_scale_px, texture_width
from nerif.sensing.vectors import median_test

log = logging.getLogger(__name__)
MEASUREMENT = Registry("measurement stage", package="nerif.sensing")
LOST_WARNING = 0.8  # a view that keeps less than this share of its region is said to, with the causes


@dataclass
class ViewMeasurement:
    """What one view's images say.

    Attributes:
        displacement: (h, w, 2) float32 image displacements [px of the full sensor] (column, row) on the ray grid,
            each a block mean of the flow's, the camera's rigid shift taken off; NaN where ``valid`` is False.
        valid: (h, w) bool: pixels with a usable measurement. Any other pixel is unknown: it carves no visual hull,
            counts as no ambient and enters no loss and no score.
        found: what was found (:class:`~nerif.sensing.findings.Findings`: the shares left out for each cause, the
            shake, the noise (:func:`noise_of`), :func:`clipped_share`, :func:`images_compared`'s figures...).
        distorted: (H, W) the distorted image the flow compared (the flame's light taken off where it was
            recorded), what an image term fits.
        flow: (H, W, 2) the flow itself on the images' grid [px of that grid], kept where asked for, else None.
        left_out: (h, w) uint8 on the ray grid: why each pixel was left out, an index into :data:`CAUSES` (0: kept),
            the first cause that took it; None where not recorded (a measurement cached by an older nerif).
    """

    displacement: np.ndarray
    valid: np.ndarray
    found: Findings = field(default_factory=Findings)
    distorted: Optional[np.ndarray] = None
    flow: Optional[np.ndarray] = None
    left_out: Optional[np.ndarray] = None


# why a pixel of the ray grid was left out (ViewMeasurement.left_out), in the order the stage decides
CAUSES = ("kept", "outside the region", "saturated", "occluded", "unmeasured", "rejected")


def _on_grid(mask: np.ndarray, h: int, w: int) -> np.ndarray:
    """An image-grid mask -> the ray grid: a block is set where any of its pixels is."""
    return resample(mask.astype(np.float32), h, w) > 0


def noise_of(distorted: np.ndarray, reference: np.ndarray, u_image: np.ndarray, valid: np.ndarray,
             quiet: Optional[np.ndarray], width_px: float, shake_px: Optional[np.ndarray] = None) -> Optional[float]:
    """The images' noise [share of full scale] (:func:`~nerif.sensing.noise.residual_noise`) on the usable pixels
    that see no flame (``quiet``), the images compared through the shake they hold there (``shake_px`` (2,)
    [image px], :func:`~nerif.sensing.shake.photometric_shift`; None: through the flow), or on every usable pixel
    through the flow where too few see no flame; ``valid``, ``quiet``: (h, w) bool on the ray grid, ``u_image``
    (H, W, 2) the flow on the images' grid, the shake included."""
    H, W = reference.shape
    where = valid & quiet if quiet is not None else valid
    if int(where.sum()) * (H * W) < MIN_PIXELS * where.size:
        where = valid
    elif shake_px is not None and quiet is not None:  # the flow reads the shake with its own gain
        u_image = np.broadcast_to(np.float32(shake_px), u_image.shape)
    return residual_noise(distorted, reference, u_image, enlarged(where, H, W), width_px)


def outside_reach(u: np.ndarray, valid: np.ndarray, quiet: Optional[np.ndarray]) -> Optional[float]:
    """The 99th percentile of the displacements' size [the unit of ``u``, (h, w, 2)] on the usable pixels that see
    no flame (``quiet``: outside the probe box's image), None where fewer than :data:`~nerif.sensing.shake.MIN_QUIET`
    are: the measurement's noise there, unless the flame reaches beyond the box or the rig puts the box elsewhere."""
    if quiet is None or int((quiet & valid).sum()) < MIN_QUIET:
        return None
    return float(np.quantile(np.linalg.norm(u[quiet & valid], axis=-1), 0.99))


def images_compared(distorted: np.ndarray, reference: np.ndarray, width_px: float,
                    contrast: Optional[np.ndarray] = None) -> dict:
    """What a view's two exposures (H, W) say of each other, for :mod:`nerif.data.diagnostics`: ``difference_rms``,
    the RMS of their difference [share of full scale] (0: the same image), and ``texture_ratio``, the distorted
    exposure's median local contrast (:func:`~nerif.sensing.occlusion.local_contrast` over the texture's width
    ``width_px``) over the reference's (about 1: the same background; near 0: black, flat or overexposed);
    ``contrast``: the reference's local contrast where the caller has it."""
    d, r = np.float32(distorted), np.float32(reference)
    ref = float(np.median(local_contrast(r, width_px) if contrast is None else contrast))
    ratio = float(np.median(local_contrast(d, width_px))) / ref if ref > 0 else 1.0
    return {"difference_rms": float(np.sqrt(np.mean((d - r) ** 2))), "texture_ratio": ratio}


def clipped_share(distorted: np.ndarray, reference: np.ndarray) -> float:
    """The share of pixels at full scale in either exposure (H, W) as recorded (the dots' centres included, which
    :func:`~nerif.sensing.saturation.saturated` keeps: they still cost accuracy)."""
    return float(np.mean((distorted >= TOP) | (reference >= TOP)))


def _either(a: Optional[np.ndarray], b: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """Two optional masks' union (None where neither is given)."""
    return b if a is None else a if b is None else a | np.asarray(b, dtype=bool)


@MEASUREMENT.register("default")
def measure_view(distorted: np.ndarray, reference: np.ndarray, flow: dict, grid_px: tuple[int, int],
                 image_binning: int = 1, region: Optional[np.ndarray] = None, quiet: Optional[np.ndarray] = None,
                 flame: Optional[np.ndarray] = None, hidden: Optional[np.ndarray] = None, name: str = "",
                 keep_flow: bool = False, saturation: bool = True, occlusion_fraction: float = 0.25,
                 shake: bool = True, median_threshold: Optional[float] = 2.0, median_eps_px: float = 0.1,
                 flow_factor="auto") -> ViewMeasurement:
    """Measure one view.

    Args:
        distorted, reference: (H, W) float images in [0, 1] of full scale on the images' grid, ``image_binning``
            sensor pixels a pixel across (1: the full sensor).
        flow: a :data:`FLOW` config. grid_px: (height, width) of the ray grid (a whole number of image pixels a
            ray, or the images' grid resampled).
        region: (height, width) bool on the ray grid: the pixels to measure (a region of interest), None: all.
        quiet: (height, width) bool on the ray grid: pixels that see no flame (outside the probe box's image),
            where the camera's shake is read; None: the bulk of the view.
        flame: (H, W) the view's exposure with the background off (the flame's own light), taken off ``distorted``
            (:func:`~nerif.sensing.flame_light.without_flame_light`) after the saturated pixels are found; None.
        hidden: (H, W) bool: pixels known to be hidden (an occluder mask the capture gives), counted as occluded
            with those the reference's texture shows; None.
        name: the view, for the log. keep_flow: keep the image-grid flow in the result.
        saturation: leave out pixels at the top of the range in either exposure (:mod:`~nerif.sensing.saturation`).
        occlusion_fraction: leave out pixels whose reference texture has less than this share of the view's background
            contrast (a burner, a mount; :mod:`~nerif.sensing.occlusion`); 0: keep all.
        shake: estimate the view's rigid shift between the exposures and take it off (:mod:`~nerif.sensing.shake`).
        median_threshold, median_eps_px: the normalised median test's threshold and noise floor [px of the full
            sensor] (:mod:`~nerif.sensing.vectors`); threshold None: no test.
        flow_factor: the flow, occlusion and the exposures compared read the images this many times smaller
            (:func:`shrunk`; not saturation, nor the noise); ``auto``: as the texture says (:func:`shrink_factor`).
    """
    (h, w), (H, W) = grid_px, reference.shape
    kept = _Kept(region, h, w)
    f, small, width, contrast = _texture(reference, flow_factor)
    found = images_compared(shrunk(distorted, f), small, width, contrast)
    found.update(flow_factor=f, clipped=clipped_share(distorted, reference))  # on the images as recorded
    detected = enlarged(occluded(small, occlusion_fraction, width, contrast), H, W) if occlusion_fraction else None
    for what, unreadable in (("saturated", saturated(distorted, reference, width_px=f * width) if saturation else None),
                             ("occluded", _either(detected, hidden))):
        found[what] = kept.drop(_on_grid(unreadable, h, w) if unreadable is not None else None, what)
    if flame is not None:
        distorted = without_flame_light(distorted, flame)
    u_image, found["normalise_px"] = _flow(flow, distorted, small, f, width)
    u = resample(u_image, h, w).astype(np.float32) * np.float32(image_binning)  # px of the full sensor
    found["unmeasured"] = kept.drop(~np.isfinite(u).all(-1), "unmeasured")
    s = _take_off_shake(u, kept.valid, quiet, name) if shake else np.zeros(2)
    held = _images_shake(distorted, reference, kept.valid, quiet, s / image_binning, f * width) * image_binning \
        if shake else s
    found.update(shake_px=[float(s[0]), float(s[1])], shake_images_px=[float(held[0]), float(held[1])])
    found["rejected"] = kept.drop(median_test(u, kept.valid, median_threshold, median_eps_px)
                                  if median_threshold else None, "rejected")
    valid = kept.valid
    u[~valid] = np.nan
    peak = float(np.linalg.norm(u[valid], axis=-1).max()) if valid.any() else 0.0
    found.update(displacement_max_px=peak, valid_fraction=float(valid.mean()),
                 outside_px=outside_reach(u, valid, quiet),
                 noise=noise_of(distorted, reference, u_image, valid, quiet, f * width,
                                held / image_binning if shake else None))
    findings = Findings(**found)
    say(findings, name, region)
    return ViewMeasurement(u, valid, findings, distorted, u_image if keep_flow else None, kept.cause)


def _texture(reference: np.ndarray, flow_factor) -> tuple[int, np.ndarray, float, np.ndarray]:
    """How the texture detectors and the flow read ``reference`` (H, W): made ``f`` times smaller where its texture
    spans many pixels (``flow_factor``: :func:`shrink_factor`'s setting); returns ``f``, the reference so, its
    texture's own width [px of the small images, measured once for every detector] and its local contrast there."""
    scale = texture_scale_px(reference)
    f = shrink_factor(scale, flow_factor)
    small = shrunk(reference, f)
    width = texture_width(small, scale if f == 1 else None)
    return f, small, width, local_contrast(small, width)


def _take_off_shake(u: np.ndarray, valid: np.ndarray, quiet: Optional[np.ndarray], name: str) -> np.ndarray:
    """The camera's rigid shift between the exposures (:func:`rigid_shift`) read on ``u`` (h, w, 2) [px of the full
    sensor] and taken off it in place; returns it (2,)."""
    s, where = rigid_shift(u, valid, quiet)
    u -= s.astype(np.float32)
    log.debug("%s: shake read %s", name, where)
    return s


def _images_shake(distorted: np.ndarray, reference: np.ndarray, valid: np.ndarray, quiet: Optional[np.ndarray],
                  start_px: np.ndarray, width_px: float) -> np.ndarray:
    """The shake [image px] (2,) the images (H, W) hold (:func:`~nerif.sensing.shake.photometric_shift`), read on
    the usable pixels that see no flame (``valid``, ``quiet``: (h, w) bool on the ray grid) from the flow's reading
    ``start_px``; that reading where too few pixels see no flame (it was read on the view's bulk, whose images hold
    the flame's displacements too)."""
    if quiet is None or int((quiet & valid).sum()) < MIN_QUIET:
        return np.asarray(start_px, dtype=np.float64)
    H, W = reference.shape
    return photometric_shift(distorted, reference, enlarged(quiet & valid, H, W), start_px, width_px)


def _flow(flow: dict, distorted: np.ndarray, small: np.ndarray, f: int, width: float) -> tuple[np.ndarray, object]:
    """(H, W, 2) the flow [px of the images as recorded] of ``distorted`` (H, W) against the reference, measured on
    both made ``f`` times smaller (``small``: the reference so; ``width``: its texture's width there), and the
    normalisation window it used [px of the images as recorded; None where it used none]."""
    if isinstance(flow.get("normalise_px"), (int, float)):  # set in px of the images as recorded
        flow = {**flow, "normalise_px": flow["normalise_px"] / f}
    u_small, normalise_px = estimate(flow, shrunk(distorted, f), small, width)
    return enlarged(u_small, *distorted.shape), (f * normalise_px if normalise_px else normalise_px)


class _Kept:
    """The pixels of a ray grid (h, w) a view's measurement keeps, and why it left out the others (``cause``,
    an index of :data:`CAUSES` each; 0: kept)."""

    def __init__(self, region: Optional[np.ndarray], h: int, w: int):
        self.valid = np.ones((h, w), bool) if region is None else np.asarray(region, dtype=bool).copy()
        self.cause = np.where(self.valid, 0, CAUSES.index("outside the region")).astype(np.uint8)

    def drop(self, lost: Optional[np.ndarray], why: str) -> float:
        """Leave out the kept pixels of ``lost`` ((h, w) bool, or None: none) for ``why`` (a :data:`CAUSES`
        name); returns their share of the grid."""
        if lost is None:
            return 0.0
        lost = lost & self.valid
        self.cause[lost] = CAUSES.index(why)
        self.valid &= ~lost
        return float(lost.mean())


def say(found: Findings, name: str, region: Optional[np.ndarray] = None) -> None:
    """The log's line of one view's measurement (``found``, :class:`ViewMeasurement`'s), and a warning where it
    keeps less than :data:`LOST_WARNING` of its ``region`` (None: the whole view), naming the causes."""
    left = ", ".join(f"{100 * share:.1f} % {k}" for k, share in (
        ("saturated", found.saturated), ("occluded", found.occluded), ("unmeasured", found.unmeasured),
        ("rejected", found.rejected)) if share > 0)
    s = found.shake_px
    log.info("%s: displacement up to %.2f px; shake (%+.3f, %+.3f) px taken off%s%s", name or "view",
             found.displacement_max_px, s[0], s[1],
             f"; flow normalised over {found.normalise_px:.1f} px" if found.normalise_px else "",
             f"; left out: {left}" if left else "")
    region_share = float(np.mean(region)) if region is not None else 1.0
    if region_share > 0 and found.valid_fraction < LOST_WARNING * region_share:
        log.warning("%s: %.0f %% of its region of interest has no usable displacement (%s): look at its images; "
                    "the settings are measure.* and flow.*", name or "view",
                    100 * (1 - found.valid_fraction / region_share), left)


def measure_cached(cache_dir, measure: dict, distorted: np.ndarray, reference: np.ndarray, name: str = "",
                   **inputs) -> tuple[ViewMeasurement, bool]:
    """``MEASUREMENT.build(measure, ...)`` of one view, stored under ``cache_dir`` and read back from there when the
    same images (their values), the same masks and grid and the same settings (``measure``, ``flow``) are measured
    again by the same measurement code (:func:`nerif.cache.cached_arrays`); ``cache_dir=None`` always measures.

    Args:
        inputs: the other arguments of :func:`measure_view` (``flow``, ``grid_px``, ``region``, ``quiet``,
            ``flame``, ``hidden``, ...), arrays or settings.
    Returns:
        the view's measurement and whether it was read from the cache (then its log line is said again).
    """
    def key(x):
        return content_digest(np.asarray(x)) if isinstance(x, np.ndarray) else x

    computed = []

    def compute() -> dict:
        m = MEASUREMENT.build(measure, distorted=distorted, reference=reference, name=name, **inputs)
        computed.append(m)
        arrays = {"displacement": m.displacement, "valid": m.valid, "found": np.array(json.dumps(m.found.report(), default=float))}
        if m.left_out is not None:
            arrays["left_out"] = m.left_out
        if m.distorted is not distorted:  # the flame's light taken off: not the image given
            arrays["distorted"] = m.distorted
        if m.flow is not None:
            arrays["flow"] = m.flow
        return arrays

    payload = {"measure": measure, "distorted": key(distorted), "reference": key(reference),
               **{k: key(v) for k, v in sorted(inputs.items())}}
    arrays = cached_arrays(cache_dir, "measured", payload, compute)
    if computed:
        return computed[0], False
    found = Findings.read(json.loads(str(arrays["found"])))
    say(found, name, inputs.get("region"))
    return ViewMeasurement(arrays["displacement"], arrays["valid"], found, arrays.get("distorted", distorted),
                           arrays.get("flow"), arrays.get("left_out")), True
