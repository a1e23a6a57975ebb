"""``data=synthetic``: a phantom seen by a synthetic rig, its observations rendered by the voxel forward model
through a sensing model (ideal, perpendicular or realistic) and cached; and the frames of a phantom that changes
in time."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from nerif.cache import cached_arrays, content_digest
from nerif.data.folders import finite_or_masked
from nerif.data.frames import FRAMES, Frame, pick_frames
from nerif.data.phantoms import PHANTOMS
from nerif.data.scene import (DATASETS, Scene, ViewImages, keep_rays, kept_pixels, scene_from_displacements,
                              views_of)
from nerif.geometry import RIGS, rays_in_box
from nerif.memory import probe_grid
from nerif.physics import Ambient
from nerif.sensing.models import SENSING
from nerif.sensing.record import MeasuredViews, SensingRecord

_SCENE_CACHE_VERSION = 7  # 7: the chain's measured views apart from its truth


def supersampled(phantom: dict, factor: int):
    """The same phantom on a grid ``factor`` times finer (same box); needs a phantom built from shape and voxel."""
    if "shape" not in phantom or "voxel_mm" not in phantom:
        raise ValueError(f"phantom '{phantom['name']}' has a fixed grid: set data.render_supersample=1")
    fine = dict(phantom, shape=[int(n) * factor for n in phantom["shape"]], voxel_mm=phantom["voxel_mm"] / factor)
    return PHANTOMS.build(fine)


@FRAMES.register("synthetic")
def synthetic_frames(phantom: dict, frames=None, frame_rate_hz: float = 250.0, **_) -> Optional[list[Frame]]:
    """``data.frames`` of a synthetic scene: None (one steady scene), else that many frames (or those listed) of
    the phantom, ``1 / frame_rate_hz`` apart from its own ``time_s``; the phantom must change in time."""
    if frames is None:
        return None
    if "time_s" not in phantom:
        raise ValueError(f"data.frames={frames}: phantom '{phantom['name']}' does not change in time; a sequence needs "
                         "one that does, such as phantom=flicker")
    if not frame_rate_hz > 0:
        raise ValueError(f"data.frame_rate_hz={frame_rate_hz}: a positive number of frames per second")
    return [Frame(k, float(phantom["time_s"]) + k / float(frame_rate_hz)) for k in pick_frames(frames)]


def _rendered_scene(ph, ambient: Ambient, cameras: list, rays: tuple, eps: torch.Tensor, record, sensing: str) -> Scene:
    """The scene of deflections ``eps`` (N, 3) rendered along ``rays`` (origins, dirs, pixel, view_start) of the
    phantom ``ph``; a ray the sensing could not render is unknown (left out, its pixel not valid)."""
    origins, dirs, pixel, view_start = rays
    keep = torch.as_tensor(finite_or_masked(eps.cpu().numpy(), f"{sensing} sensing"), device=eps.device)
    views = views_of(cameras)
    if not keep.all():
        views = views_of(cameras, valid=kept_pixels(cameras, pixel, view_start, keep))
        dirs, eps, pixel, view_start = keep_rays(dirs, eps, pixel, view_start, keep)
    return Scene(box=ph.box, ambient=ambient, views=views, origins=origins, dirs=dirs, eps=eps, pixel=pixel,
                 view_start=view_start, truth_T=ph.T, sensing=record, perpendicular_only=sensing != "ideal")


def _phantom_voxels(phantom) -> Optional[float]:
    """Voxels of the phantom's grid: its ``shape``, or the header of a ``.npy`` file (other files: unknown)."""
    if "shape" in phantom and phantom["shape"] is not None:
        return float(np.prod([float(n) for n in phantom["shape"]]))
    path = phantom.get("path")
    if path and str(path).endswith(".npy") and Path(str(path)).expanduser().is_file():
        try:
            return float(np.prod(np.load(Path(str(path)).expanduser(), mmap_mode="r").shape))
        except (OSError, ValueError):
            return None
    return None


def allocations(cfg) -> list[tuple[str, str, float]]:
    """What a synthetic scene allocates (:mod:`nerif.memory`): the phantom and its deflection field on the
    supersampled rendering grid (float64), and the probe grid; nothing known where the phantom's grid is not."""
    voxels = _phantom_voxels(cfg["phantom"])
    if voxels is None:
        return []
    ss = float(cfg["data"]["render_supersample"])
    return [("the phantom on the rendering grid", "data.render_supersample", voxels * ss**3 * 8 * 4),
            probe_grid(voxels, "phantom.shape")]


def _observed(fine, sensing: dict, cameras: list, rays: tuple, step_mm: Optional[float], cache_dir,
              device: str) -> dict:
    """What the ``sensing`` config (a :data:`SENSING` entry and its parameters) observes of the phantom ``fine``
    (its rendering grid) through ``cameras`` along ``rays`` (dirs, pixel, view_start), as the cache keeps it:
    ``eps`` (deflections) or ``measured/...`` (a measurement's views), and the record's ``sensing/...``."""
    dirs, pixel, view_start = rays
    delta = torch.as_tensor(fine.delta, dtype=torch.float32, device=device)
    observed, record = SENSING.build(sensing, delta=delta, box=fine.box, cameras=cameras, dirs=dirs, pixel=pixel,
                                     view_start=view_start, step_mm=step_mm, rig_binning=cameras[0].binning,
                                     cache_dir=cache_dir)
    seen = ({f"measured/{k}": v for k, v in observed.arrays().items()} if isinstance(observed, MeasuredViews)
            else {"eps": observed.cpu().numpy()})
    return {**seen, **{f"sensing/{k}": v for k, v in (record.arrays() if record else {}).items()}}


@DATASETS.register("synthetic", hints={"binning": "rig.binning"}, allocations=allocations)
def synthetic(phantom: dict, rig: dict, T_max: float, sensing: str = "ideal", sensor: Optional[dict] = None,
              render_supersample: int = 4, render_step_mm: Optional[float] = None, cache_dir: Optional[str] = None,
              deflection_noise: float = 0.0, noise_seed: int = 0, frames=None, frame_rate_hz: float = 250.0,
              frame: Optional[int] = None, device: str = "cpu") -> Scene:
    """A phantom seen by a synthetic rig; observations from the voxel forward model.

    Args:
        phantom: phantom config (``name`` + parameters). rig: a :data:`nerif.geometry.RIGS` config.
        T_max: hottest expected temperature [K] (sets delta_thre).
        sensing: a :data:`SENSING` entry: ``ideal`` (thin rays, noise-free deflection vectors), ``perpendicular``
            (the same, only the part a camera measures) or ``realistic`` (finite aperture, background pattern,
            noise, optical flow: :func:`nerif.sensing.realistic.realistic` with the ``sensor`` parameters).
        render_supersample: the observations are rendered from the phantom on a grid this many times finer
            (a coarse voxel forward model misses the deflections of a continuous field: 9% on Phantom 5 at
            2 mm, 0.7% at 0.5 mm); the reconstruction is evaluated on the phantom's own grid.
        render_step_mm: quadrature step of the observations (default half a rendering voxel).
        cache_dir: where observations are cached, keyed by the config that made them (None: no cache).
        deflection_noise: Gaussian noise added to the observed deflections, as a fraction of their RMS magnitude
            (the RMS magnitude of the noise vectors; perpendicular to each ray where only that part is measured),
            drawn with ``noise_seed``.
        frames, frame_rate_hz: the frames of a sequence (:func:`synthetic_frames`); ``frame``: the one to build,
            the phantom at its ``time_s + frame / frame_rate_hz`` (None: at its own ``time_s``), with noise
            drawn for that frame.
    """
    SENSING.get(sensing)  # an unknown name fails here, before any rendering
    if frame is not None:
        phantom = dict(phantom, time_s=synthetic_frames(phantom, [int(frame)], frame_rate_hz)[0].time_s)
    if not 0.0 <= deflection_noise < 10.0:
        raise ValueError(f"data.deflection_noise={deflection_noise}: a fraction of the RMS deflection, within [0, 10)")
    sensor = dict(sensor or {}) if sensing == "realistic" else {}  # the only sensing with parameters
    ph = PHANTOMS.build(phantom)
    ambient = Ambient(ph.T0, ph.n0, float(T_max))
    cameras = RIGS.build(rig)
    origins, dirs, pixel, view_start = rays_in_box(ph.box, cameras, device)

    def observe() -> dict:
        fine = supersampled(phantom, render_supersample) if render_supersample > 1 else ph
        return _observed(fine, {"name": sensing, **sensor}, cameras, (dirs, pixel, view_start), render_step_mm,
                         cache_dir, device)

    payload = {"v": _SCENE_CACHE_VERSION, "truth": content_digest(ph.T), "phantom": phantom, "rig": rig, "step": render_step_mm,
               "supersample": render_supersample, "sensing": sensing, "sensor": sensor}
    arrays = cached_arrays(cache_dir, "synthetic", payload, observe)
    sensed, measured = ({k[len(p):]: v for k, v in arrays.items() if k.startswith(p)}
                        for p in ("sensing/", "measured/"))
    record = SensingRecord.from_arrays(sensed) if sensed else None
    if "eps" not in arrays:  # measured from images: built as a capture is, from each view's displacements
        scene = replace(measured_scene(ph, ambient, cameras, (origins, dirs, pixel, view_start),
                                       MeasuredViews.from_arrays(measured), record, sensor, device),
                        cache_dir=cache_dir)
    else:
        scene = _rendered_scene(ph, ambient, cameras, (origins, dirs, pixel, view_start),
                                torch.as_tensor(arrays["eps"], device=device), record, sensing)
    if deflection_noise > 0:  # each frame of a series has noise of its own, as each exposure does
        seed = noise_seed if frame is None else noise_seed + 7919 * (int(frame) + 1)
        eps = with_noise(scene.eps, scene.dirs if scene.perpendicular_only else None, deflection_noise, seed)
        scene = replace(scene, eps=eps, displacements=None)  # the displacements follow the noisy deflections
    return scene


def measured_scene(ph, ambient: Ambient, cameras: list, rays: tuple, measured: MeasuredViews,
                   record: SensingRecord, sensor: dict, device) -> Scene:
    """The scene of a realistic chain's views (``measured``): each view's measured displacements, valid pixels,
    images and findings, through :func:`nerif.data.scene.scene_from_displacements` (as a capture's), with the chain's
    truth (``record``)."""
    binning = int(sensor.get("image_binning", 1))
    images = [ViewImages(torch.as_tensor(measured.reference[v] / 255.0, dtype=torch.float32, device=device),
                         torch.as_tensor(measured.distorted[v] / 255.0, dtype=torch.float32, device=device),
                         cam.full_sensor.binned(binning)) for v, cam in enumerate(cameras)]
    return scene_from_displacements(ph.box, ambient, cameras, list(measured.displacement_px), list(measured.valid),
                                    device=device, rays=rays, images=images, found=measured.findings(), truth_T=ph.T,
                                    sensing=record, left_out=list(measured.left_out))


def with_noise(eps: torch.Tensor, dirs: Optional[torch.Tensor], fraction: float, seed: int) -> torch.Tensor:
    """``eps`` (N, 3) plus Gaussian noise whose RMS magnitude is ``fraction`` of the RMS of ``|eps|``; the noise
    lies perpendicular to ``dirs`` (N, 3) when given (2 components), else it has 3."""
    g = torch.Generator().manual_seed(int(seed))
    noise = torch.randn(eps.shape, generator=g, dtype=torch.float64)
    if dirs is not None:
        d = dirs.detach().cpu().double()
        noise = noise - (noise * d).sum(-1, keepdim=True) * d
    rms = eps.double().norm(dim=-1).pow(2).mean().sqrt().cpu()
    noise = noise * (fraction * rms / noise.norm(dim=-1).pow(2).mean().sqrt())
    return (eps.double() + noise.to(eps.device)).to(eps.dtype)
