"""BOS captures as an experimentalist records them: a folder of background images and a rig file, ``rig.yaml``
(:mod:`nerif.data.rig_file`; the format, with every key explained, is in ``docs/captures.md``).

The pipeline: the rig file read once (:func:`nerif.data.rig_file.read_rig`), the images of a frame decoded once
(:mod:`nerif.data.capture_images`), each view measured by the measurement stage
(:func:`nerif.sensing.measurement.measure_view`: the optical flow, block means to the ray grid, validity), the
displacements kept by the scene with their deflections through the rig geometry, on the rays inside the region of
interest that cross the probe box. A pixel's ray leaves from its undistorted position; images, flow and masks stay
on the distorted pixel grid. Everything that can be wrong with the folder is checked before the flow runs, for
every frame of a time series before the first frame's flow. The cameras and their rays are built once for all
the frames of a series (:func:`rig_geometry`).
"""
from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from nerif.data.capture_images import capture_files, check_images, lossy_images, occluder_masks, read_exposures
from nerif.data.folders import blocks_inside, dataset_folder, read_truth, region_of_interest, resolve_binning
from nerif.data.frames import FRAMES, Frame, pick_frames
from nerif.data.rig_file import RigFile, read_rig
from nerif.data.diagnostics import box_fills_frame, least_unseen_view, screened
from nerif.data.scene import (DATASETS, Scene, ViewImages, heldout_views,
                              scene_from_displacements)
from nerif.geometry import Camera, outside_the_box, rays_in_box
from nerif.memory import FLOAT, probe_grid
from nerif.physics import Ambient
from nerif.sensing.flow import FLOW, check_flow
from nerif.sensing.interpolation import INTERPOLATIONS
from nerif.sensing.measurement import MEASUREMENT, measure_cached

log = logging.getLogger(__name__)


def rig_cameras(rig: RigFile, binning=1) -> tuple[list[Camera], list[Camera]]:
    """The rig's cameras on the full sensor, and the same read out with ``binning`` (``auto``: about one ray per
    voxel of the probe box across, :func:`nerif.geometry.ray_binning`, logged)."""
    full = rig.cameras()
    w, h = rig.sensor_px
    binning = resolve_binning(binning, full, rig.box, f"the sensor size {w} x {h} px")
    return full, [cam.binned(binning) if binning > 1 else cam for cam in full]


def roi_mask(rig: RigFile, binning: int) -> np.ndarray:
    """(height, width) bool on the ray grid: blocks wholly inside the region of interest."""
    w, h = rig.sensor_px
    x, y, dw, dh = rig.roi_px
    roi = region_of_interest(x, y, dw, dh, w, h, f"{rig.path}: roi_px {list(rig.roi_px)} (x, y, width, height)")
    return blocks_inside(roi, h // binning, w // binning)


_GEOMETRY: dict = {}  # the last capture's geometry, keyed by everything it is built from


def rig_geometry(rig: RigFile, binning, device) -> tuple[list[Camera], list[Camera], np.ndarray, tuple]:
    """The full-sensor and ray-grid cameras, the region of interest on the ray grid and the rays that cross the
    probe box (:func:`nerif.geometry.rays_in_box`), checked: every camera sees the box within the region of
    interest. Built once for the frames of a series: kept while the files the rig is read from, the binning and the
    device stay the same."""
    key = (str(rig.path.resolve()), _rig_digest(rig), str(binning), str(device))
    if _GEOMETRY.get("key") != key:
        _GEOMETRY.clear()
        full, cameras = rig_cameras(rig, binning)
        roi = roi_mask(rig, cameras[0].binning)
        rays = rays_in_box(rig.box, cameras, device)  # a camera that does not see the box fails here, before the flow
        pixel, starts = rays[2].cpu(), rays[3].cpu()
        for v, cam in enumerate(cameras):
            if not roi.reshape(-1)[pixel[starts[v]:starts[v + 1]].numpy()].any():
                raise ValueError(f"{cam.name}: no pixel of roi_px {list(rig.roi_px)} sees the probe box "
                                 f"{rig.box.extent_mm.tolist()} mm ({rig.path}): check the region of interest, the "
                                 "distances and the probe box")
        _GEOMETRY.update(key=key, value=(full, cameras, roi, rays))
    return _GEOMETRY["value"]


def _rig_digest(rig: RigFile) -> str:
    """A digest of the files the cameras are read from (the rig file, its calibration file)."""
    h = hashlib.sha256()
    for p in rig.sources:
        h.update(str(p).encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


_REFERENCES: dict = {}  # the last capture's reference images (and flame-only ones), keyed by their files


def reference_images(views: list[tuple[Path, ...]], sensor_px, kind: str = "reference"
                     ) -> tuple[list[np.ndarray], list[Optional[float]]]:
    """Images every frame of a series shares (the references, the flame-only exposures, the occluder masks), each
    view's the mean of its exposures with its noise (:func:`read_exposures`), decoded once (again when a file
    changes)."""
    key = tuple((str(p.resolve()), p.stat().st_mtime_ns, p.stat().st_size) for files in views for p in files)
    if _REFERENCES.get(kind, {}).get("key") != key:
        _REFERENCES[kind] = {"key": key, "value": read_exposures(views, sensor_px)}
    return _REFERENCES[kind]["value"]


def sigma_prior(rig: RigFile, ambient: Ambient) -> Optional[tuple]:
    """The field's interval from the rig's ``temperature_range_K`` (with ambient, sigma = 0, inside it and a 0.05
    margin), or None."""
    if rig.temperature_range_K is None:
        return None
    lo, hi = rig.temperature_range_K
    s_hot, s_cold = ambient.sigma_from_temperature(hi), ambient.sigma_from_temperature(lo)
    return min(s_hot, 0.0) - 0.05, max(s_cold, 0.0) + 0.05


@FRAMES.register("capture")
def capture_frames(root: str, frames=None, **_) -> Optional[list[Frame]]:
    """``data.frames`` of a capture folder: None for a folder of one frame (unless frames are asked for), else
    every frame (null) or those picked; every picked frame's files are checked (present, listed, readable, of
    the sensor's size and one bit depth, from their headers) before any flow runs."""
    rig = read_rig(dataset_folder(root))
    if frames is None and len(rig.frames) == 1:
        return None
    picked = pick_frames(frames, len(rig.frames))
    distorted, references = [], []
    for k in picked:
        d, references = capture_files(rig, k)
        distorted += d
    check_images([p for files in distorted + references for p in files], rig.sensor_px)
    return [Frame(k, rig.frames[k].time_s) for k in picked]


PER_PIXEL = 24  # bytes an image pixel of a capture's view takes over a run (both images, as read, measured, band-passed
               # and as B-spline coefficients): 6.0 GiB at 10 views of 25 megapixels, 1.2 GiB of it the run's own


def allocations(cfg) -> list[tuple[str, str, float]]:
    """What a capture allocates (:mod:`nerif.memory`), read from its rig file (checked as :func:`capture` reads it):
    one frame's images of every view at the sensor's size (:data:`PER_PIXEL` a pixel, and ``factor^2 - 1`` floats
    more where the image term reads each reference on a grid ``factor`` times finer,
    ``data_term.interpolation``; counted whatever the solver, an upper bound), and the probe grid."""
    rig = read_rig(dataset_folder(cfg["data"]["root"]))
    w, h = rig.sensor_px
    read = (cfg.get("data_term") or {}).get("interpolation")  # an unknown one: the data term refuses it
    factor = INTERPOLATIONS.get(read).factor if read in INTERPOLATIONS else 1
    return [("the images", f"the views in {rig.path} (fewer views, or images cropped to the flame)",
             float(rig.n_views * w * h) * (PER_PIXEL + FLOAT * (factor**2 - 1))),
            probe_grid(float(np.prod(rig.box.shape)), f"probe.shape in {rig.path}")]


def _record_exposures(measured, cached, cache_dir, distorted, references, noise, ref_noise) -> None:
    """Each view's measurement told (its ``found``) whether it was read from the cache, how many exposures each
    of its images averaged and the noise of their means; the log says so where it matters."""
    if any(cached):
        log.info("measurements of %d of %d views read from the cache in %s (the same images, masks and settings "
                 "measured before; data.cache_dir=null measures again)", sum(cached), len(cached), cache_dir)
    for m, c, d, r, nd, nr in zip(measured, cached, distorted, references, noise, ref_noise):
        # K exposures averaged per image
        m.found.from_cache, m.found.exposures = bool(c), [len(d), len(r)]
        m.found.image_noise, m.found.reference_noise = nd, nr
    if any(len(f) > 1 for f in distorted + references):
        log.info("exposures averaged per view: %s distorted, %s reference; noise of the means %s",
                 "/".join(str(len(f)) for f in distorted), "/".join(str(len(f)) for f in references),
                 ", ".join("-" if n is None else f"{100 * n:.2f} %" for n in noise))


def held_out(heldout: Optional[list], rig, cameras: list) -> list[int]:
    """The views never trained on: ``data.heldout`` where set, else the rig file's ``heldout``, else the view whose
    absence leaves the fewest directions unseen (:func:`nerif.data.diagnostics.least_unseen_view`)."""
    if heldout is not None:
        return heldout_views(heldout, len(cameras), "data.heldout")
    listed = [least_unseen_view(cameras)] if rig.heldout is None else list(rig.heldout)
    return heldout_views(listed, len(cameras), f"{rig.path}: heldout")


@DATASETS.register("capture", allocations=allocations)
def capture(root: str, flow: dict, measure: Optional[dict] = None, binning="auto", heldout: Optional[list] = None,
            frames=None, frame: Optional[int] = None, truth: Optional[str] = None, cache_dir=None,
            device: str = "cpu") -> Scene:
    """A capture folder -> scene of the training views, with the held-out views as ``scene.heldout``.

    Args:
        root: the capture folder. flow: a :data:`nerif.sensing.flow.FLOW` config. measure: a
            :data:`nerif.sensing.measurement.MEASUREMENT` config (None: the default stage).
        binning: b x b sensor pixels averaged into one ray (the ray grid); ``auto``: about one ray per voxel
            across at the probe (:func:`nerif.geometry.ray_binning`), logged.
        heldout: views never trained on (overrides the rig file's ``heldout``; default: the view whose absence
            leaves the fewest directions unseen, :func:`nerif.data.diagnostics.least_unseen_view`).
        frames: the frames of a time series (:func:`capture_frames`); ``frame``: the one to build (None: the
            first of the folder).
        truth: a volume file of the true temperature [K] on the probe grid, for a rendered capture (its array
            ``T``): every error against the truth is then reported. None for a real experiment.
        cache_dir: where each view's measurement is kept (:func:`nerif.sensing.measurement.measure_cached`: keyed
            by its images' values, masks, grid and settings), so that another run of the same capture skips the
            optical flow; None: measured every time.
    """
    rig = read_rig(dataset_folder(root))
    FLOW.get(flow["name"])
    measure = dict(measure or {"name": "default"})
    MEASUREMENT.get(measure["name"])
    frame = 0 if frame is None else int(frame)
    if not 0 <= frame < len(rig.frames):
        raise ValueError(f"frame {frame}: {rig.path} lists {len(rig.frames)} frame(s)")
    distorted, references = capture_files(rig, frame)
    flame = [rig.root / f for f in rig.flame_only or ()]
    files = [p for exposed in distorted + references for p in exposed]
    check_images(files + flame, rig.sensor_px)  # one bit depth for all, from the headers
    full, cameras, roi, rays = rig_geometry(rig, binning, device)
    quiet = outside_the_box(cameras, rays[2], rays[3])
    box_fills_frame(cameras, quiet, roi, rig.box, str(rig.path))  # a scale off by a factor, before any image is read
    held = held_out(heldout, rig, cameras)
    prior = sigma_prior(rig, rig.ambient)
    truth_T = read_truth(truth, rig.box) if truth is not None else None
    if lossy := lossy_images(files):
        log.warning("%s", lossy)
    (images, noise), (refs, ref_noise) = read_exposures(distorted, rig.sensor_px), reference_images(references,
                                                                                                    rig.sensor_px)
    flames = reference_images([(p,) for p in flame], rig.sensor_px, "flame")[0] if flame else [None] * len(images)
    hidden = occluder_masks(rig, lambda paths: reference_images([(p,) for p in paths], rig.sensor_px, "occluders")[0])
    check_flow(flow)  # settings that cannot measure say so once, not as an empty view each
    measured, cached = zip(*[measure_cached(cache_dir, measure, images[v], refs[v], name=cam.name, flow=flow,
                                            flame=flames[v], hidden=hidden[v], grid_px=(cam.height, cam.width),
                                            region=roi, quiet=quiet[v])
                             for v, cam in enumerate(cameras)])
    _record_exposures(measured, cached, cache_dir, distorted, references, noise, ref_noise)
    views = [ViewImages(torch.as_tensor(r, device=device), torch.as_tensor(m.distorted, device=device), cam)
             for r, m, cam in zip(refs, measured, full)]
    causes = [m.left_out for m in measured]
    scene = scene_from_displacements(rig.box, rig.ambient, cameras, [m.displacement for m in measured],
                                     [m.valid for m in measured], device=device, rays=rays, sigma_prior=prior,
                                     sigma_prior_from=f"temperature_range_K {list(rig.temperature_range_K or ())} in "
                                                      f"{rig.path}",
                                     images=views, truth_T=truth_T, found=[m.found for m in measured],
                                     cache_dir=cache_dir,
                                     left_out=causes if all(c is not None for c in causes) else None)
    return screened(scene, held)
