"""A scene: the probe box, the cameras, and every camera ray that crosses the box with its observed deflection.

Rays of all views are stored concatenated (``dirs``, ``eps``) with ``view_start`` offsets, so drawing a batch
from one view is one slice and one random index, on any device.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Optional

import numpy as np
import torch

from nerif.cache import cached_arrays, content_digest
from nerif.data.frames import FRAMES, Frame, pick_frames
from nerif.data.phantoms import PHANTOMS
from nerif.geometry import RIGS, Camera, ProbeBox, rays_in_box, view_index
from nerif.physics import Ambient
from nerif.registry import Registry
from nerif.renderers.deflection import perpendicular
from nerif.sensing.imaging import resample
from nerif.sensing.models import SENSING

log = logging.getLogger(__name__)
DATASETS = Registry("dataset", package="nerif.data")
_SCENE_CACHE_VERSION = 5


@dataclass
class Scene:
    """Rays and observations of a BOS experiment.

    Attributes:
        box: the probe box (reconstruction grid).
        ambient: T0, n0 and the normalisation scale delta_thre.
        cameras: the V cameras.
        origins: (V, 3) camera centres [mm].
        dirs: (N, 3) unit directions of every ray that crosses the box, grouped by view.
        eps: (N, 3) observed world-frame deflections [rad].
        pixel: (N,) flat pixel index (row * width + column) of each ray in its camera.
        view_start: (V + 1,) offsets of each view's rays.
        truth_T: (nx, ny, nz) true temperature [K] on ``box`` where known (synthetic scenes), else None.
        perpendicular_only: the observations are only the part of each deflection perpendicular to its ray, as
            measured through image displacements (their along-ray component is zero and means nothing); solvers
            then compare only that part. False for ideal sensing (full vectors).
        sensing: what realistic sensing produced (images, true and estimated displacements; see
            :func:`nerif.sensing.realistic.realistic`), else None.
        mask_images: per view, (height, width) bool 2-D masks that came with the data (the mask builders then
            use them instead of thresholding the deflections), else None.
        heldout: the views kept out of training, as a scene of their own (same box and ambient), else None.
        sigma_prior: (a, b) interval of sigma the data say the field lies in, else None (the field's default).
    """

    box: ProbeBox
    ambient: Ambient
    cameras: list[Camera]
    origins: torch.Tensor
    dirs: torch.Tensor
    eps: torch.Tensor
    pixel: torch.Tensor
    view_start: torch.Tensor
    truth_T: Optional[np.ndarray] = None
    sensing: Optional[dict] = None
    perpendicular_only: bool = False
    mask_images: Optional[list] = None
    heldout: Optional["Scene"] = None
    sigma_prior: Optional[tuple] = None

    @property
    def n_views(self) -> int:
        return len(self.cameras)

    def view_slice(self, view: int) -> slice:
        """The rays of ``view`` in ``dirs``, ``eps`` and ``pixel``."""
        return slice(int(self.view_start[view]), int(self.view_start[view + 1]))

    def view_counts(self) -> torch.Tensor:
        return self.view_start[1:] - self.view_start[:-1]

    def ray_views(self) -> torch.Tensor:
        """(N,) view index of every ray."""
        return view_index(self.view_start)

    def select_views(self, views) -> "Scene":
        """The scene of only ``views`` (indices, in that order), without held-out views or sensing record."""
        vs = [int(v) for v in views]
        if not vs or any(not 0 <= v < self.n_views for v in vs):
            raise ValueError(f"views {vs} must be a non-empty list within 0..{self.n_views - 1}")
        dev = self.dirs.device
        idx = torch.cat([torch.arange(int(self.view_start[v]), int(self.view_start[v + 1]), device=dev) for v in vs])
        counts = torch.tensor([int(self.view_start[v + 1] - self.view_start[v]) for v in vs], device=dev)
        starts = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
        masks = [self.mask_images[v] for v in vs] if self.mask_images is not None else None
        return replace(self, cameras=[self.cameras[v] for v in vs], origins=self.origins[vs], dirs=self.dirs[idx],
                       eps=self.eps[idx], pixel=self.pixel[idx], view_start=starts, mask_images=masks, heldout=None,
                       sensing=None)

    def split_views(self, heldout) -> "Scene":
        """The scene of every view but ``heldout``, with those as its ``heldout`` scene."""
        held = heldout_views(heldout, self.n_views)
        train = self.select_views([v for v in range(self.n_views) if v not in held])
        train.heldout = self.select_views(held)
        return train

    def view_image(self, view: int, values: np.ndarray, fill: float = 0.0) -> np.ndarray:
        """Per-ray values (R_view,) or (R_view, C) of ``view`` on its camera's pixel grid, ``fill`` where it has no
        ray: (height, width) or (height, width, C)."""
        cam, values = self.cameras[view], np.asarray(values)
        img = np.full((cam.height * cam.width,) + values.shape[1:], fill, dtype=np.float64)
        img[self.pixel[self.view_slice(view)].cpu().numpy()] = values
        return img.reshape((cam.height, cam.width) + values.shape[1:])

    def to(self, device) -> "Scene":
        return replace(self, origins=self.origins.to(device), dirs=self.dirs.to(device), eps=self.eps.to(device),
                       pixel=self.pixel.to(device), view_start=self.view_start.to(device),
                       heldout=self.heldout.to(device) if self.heldout is not None else None)


def scene_from_images(box: ProbeBox, ambient: Ambient, cameras: list[Camera], eps_images: list[np.ndarray],
                      valid: list[np.ndarray], device="cpu", **fields) -> Scene:
    """A scene of measured deflections: per view, the image pixels that are ``valid`` and whose ray crosses the box.

    Args:
        eps_images: per view, (height, width, 3) world-frame deflections [rad], as measured through image
            displacements; they are stored perpendicular to each ray (see :func:`perpendicular`).
        valid: per view, (height, width) bool: the region of interest and finite data.
        fields: further :class:`Scene` fields (``mask_images``, ``heldout``, ``sensing``).
    Raises a clear error for a view with no valid pixel on the box.
    """
    origins, dirs, pixel, view_start = rays_in_box(box, cameras, device)
    eps = torch.cat([torch.as_tensor(img.reshape(-1, 3), dtype=torch.float32, device=device)[pixel[view_start[v]:view_start[v + 1]]]
                     for v, img in enumerate(eps_images)])
    keep = torch.cat([torch.as_tensor(ok.reshape(-1), device=device)[pixel[view_start[v]:view_start[v + 1]]]
                      for v, ok in enumerate(valid)])
    keep &= torch.isfinite(eps).all(-1)
    dirs, eps, pixel, view_start = keep_rays(dirs, eps, pixel, view_start, keep)
    for v, n in enumerate(view_start.diff().tolist()):
        if n == 0:
            raise ValueError(f"{cameras[v].name}: no pixel of its region of interest sees the probe box "
                             f"{box.extent_mm.tolist()} mm: check the region of interest, the pose and the probe box")
    return Scene(box, ambient, cameras, origins, dirs, perpendicular(eps, dirs), pixel, view_start,
                 perpendicular_only=True, **fields)


def view_directions(cameras: list[Camera], tol_deg: float = 1.0) -> int:
    """How many distinct directions the cameras look along (axes within ``tol_deg`` count as one, as do opposite
    ones: a ray and its reverse see the same line integral)."""
    axes = [np.asarray(c.rotation)[:, 2] for c in cameras]
    distinct: list[np.ndarray] = []
    for a in axes:
        if all(abs(float(a @ b)) < np.cos(np.deg2rad(tol_deg)) for b in distinct):
            distinct.append(a)
    return len(distinct)


def heldout_views(heldout, n_views: int) -> list[int]:
    """Sorted distinct held-out view indices, checked: within range and leaving a view to train on."""
    held = sorted({int(v) for v in heldout})
    if any(not 0 <= v < n_views for v in held):
        raise ValueError(f"held-out views {held} must be within 0..{n_views - 1}")
    if len(held) >= n_views:
        raise ValueError(f"all {n_views} views are held out: at least one must be trained on")
    return held


def region_of_interest(x: int, y: int, w: int, h: int, width: int, height: int, what: str) -> np.ndarray:
    """(height, width) bool, True on the pixels [x, x + w) x [y, y + h) (0-based); a clear error naming ``what``
    when the rectangle is not inside the image."""
    if not (0 <= x and 0 <= y and w > 0 and h > 0 and x + w <= width and y + h <= height):
        raise ValueError(f"{what} is not inside the {width} x {height} px image")
    roi = np.zeros((height, width), bool)
    roi[y:y + h, x:x + w] = True
    return roi


def blocks_inside(region: np.ndarray, height: int, width: int) -> np.ndarray:
    """A (H, W) bool region -> (height, width) bool on a coarser grid of the same sensor: blocks wholly inside."""
    return resample(region.astype(np.float32), height, width) > 1 - 1e-6


def dataset_folder(root) -> Path:
    """``data.root`` as an existing folder, or a clear error."""
    if root in (None, "", "???"):
        raise ValueError("data.root is not set: give the dataset folder, e.g. data.root=/path/to/folder")
    path = Path(str(root)).expanduser()
    if not path.is_dir():
        raise FileNotFoundError(f"data.root={root} is not a folder")
    return path


def finite_or_masked(u: np.ndarray, what: str) -> np.ndarray:
    """(..., 2) displacements -> (...) bool, False where a component is NaN or infinite (with a warning)."""
    ok = np.isfinite(u).all(-1)
    bad = int(ok.size - ok.sum())
    if bad:
        log.warning("%s: %d of %d displacement estimates are not finite; those rays are left out", what, bad, ok.size)
    return ok


def supersampled(phantom: dict, factor: int):
    """The same phantom on a grid ``factor`` times finer (same box); needs a phantom built from shape and voxel."""
    if "shape" not in phantom or "voxel_mm" not in phantom:
        raise ValueError(f"phantom '{phantom['name']}' has a fixed grid: set data.render_supersample=1")
    fine = dict(phantom, shape=[int(n) * factor for n in phantom["shape"]], voxel_mm=phantom["voxel_mm"] / factor)
    return PHANTOMS.build(fine)


def keep_rays(dirs, eps, pixel, view_start, keep: torch.Tensor):
    """The rays where ``keep`` (N,) is True, with the view offsets recomputed."""
    counts = torch.bincount(view_index(view_start)[keep], minlength=len(view_start) - 1)
    starts = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
    return dirs[keep], eps[keep], pixel[keep], starts


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


@DATASETS.register("synthetic", hints={"binning": "rig.binning"})
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
        delta = torch.as_tensor(fine.delta, dtype=torch.float32, device=device)
        eps, record = SENSING.build({"name": sensing, **sensor}, delta=delta, box=fine.box, cameras=cameras, dirs=dirs,
                                    pixel=pixel, view_start=view_start, step_mm=render_step_mm,
                                    rig_binning=cameras[0].binning, cache_dir=cache_dir)
        return {"eps": eps.cpu().numpy(), **{f"sensing/{k}": v for k, v in (record or {}).items()}}

    payload = {"v": _SCENE_CACHE_VERSION, "truth": content_digest(ph.T), "phantom": phantom, "rig": rig, "step": render_step_mm,
               "supersample": render_supersample, "sensing": sensing, "sensor": sensor}
    arrays = cached_arrays(cache_dir, "synthetic", payload, observe)
    eps = torch.as_tensor(arrays["eps"], device=device)
    record = {k[len("sensing/"):]: v for k, v in arrays.items() if k.startswith("sensing/")} or None
    keep = torch.as_tensor(finite_or_masked(eps.cpu().numpy(), f"{sensing} sensing"), device=device)
    if not keep.all():
        dirs, eps, pixel, view_start = keep_rays(dirs, eps, pixel, view_start, keep)
    measured_only = sensing != "ideal"  # every sensing but ideal goes through image displacements
    if deflection_noise > 0:  # each frame of a series has noise of its own, as each exposure does
        seed = noise_seed if frame is None else noise_seed + 7919 * (int(frame) + 1)
        eps = with_noise(eps, dirs if measured_only else None, deflection_noise, seed)
    return Scene(ph.box, ambient, cameras, origins, dirs, eps.to(device), pixel, view_start, ph.T, record,
                 perpendicular_only=measured_only)


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
