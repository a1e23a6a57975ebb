"""A scene: the probe box, the cameras, and every camera ray that crosses the box with its observed deflection.

Rays of all views are stored concatenated (``dirs``, ``eps``) with ``view_start`` offsets, so drawing a batch
from one view is one slice and one random index, on any device.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Optional

import numpy as np
import torch

from nerif.geometry import Camera, ProbeBox, ray_spacing_mm, rays_in_box, view_index
from nerif.physics import Ambient
from nerif.registry import Registry
from nerif.renderers.deflection import perpendicular
from nerif.sensing.findings import Findings
from nerif.sensing.displacement import displacement_matrix, displacement_to_deflection
from nerif.sensing.record import SensingRecord

DATASETS = Registry("dataset", package="nerif.data")


@dataclass(frozen=True)
class ViewImages:
    """One view's background images, what an image data term fits (:mod:`nerif.losses.images`).

    Attributes:
        reference: (H, W) the background without the flame, intensities in [0, 1].
        distorted: (H, W) the background seen through the flame: pixel x shows the reference at x + u(x).
        camera: the camera on the images' pixel grid (its full sensor, or the grid the images were binned to).
    """

    reference: torch.Tensor
    distorted: torch.Tensor
    camera: Camera

    def to(self, device) -> "ViewImages":
        return replace(self, reference=self.reference.to(device), distorted=self.distorted.to(device))


@dataclass(frozen=True)
class View:
    """One camera's record in a scene: everything that is per view besides its rays, so that selecting views
    carries all of it.

    Attributes:
        camera: the camera on the ray grid.
        images: its reference and distorted background images, where the data have them (captures, realistic
            sensing), else None.
        valid: (height, width) bool on the ray grid: the pixels with a usable measurement, where the data lack some
            (a region of interest, a flow without an estimate), else None (every pixel). Any other pixel is
            unknown: it has no ray, carves no visual hull and counts as no ambient.
        mask: (height, width) bool 2-D mask that came with the data (the mask builders then use it instead of
            thresholding the deflections), else None.
        found: what the measurement stage found in this view (:class:`nerif.sensing.findings.Findings`), None
            where the data were not measured from images.
        measured_px: (height, width, 2) the stage's displacements on the whole ray grid [px of the full sensor],
            NaN where left out, and ``left_out`` (height, width) uint8 why each pixel was (an index into
            :data:`nerif.sensing.measurement.CAUSES`, 0: kept): for the view's picture; None where not measured.
    """

    camera: Camera
    images: Optional[ViewImages] = None
    valid: Optional[np.ndarray] = None
    mask: Optional[np.ndarray] = None
    found: Optional[Findings] = None
    measured_px: Optional[np.ndarray] = None
    left_out: Optional[np.ndarray] = None

    def to(self, device) -> "View":
        return replace(self, images=self.images.to(device)) if self.images is not None else self


def views_of(cameras: list[Camera], images: Optional[list] = None, valid: Optional[list] = None,
             masks: Optional[list] = None, found: Optional[list] = None, measured_px: Optional[list] = None,
             left_out: Optional[list] = None) -> list[View]:
    """Per-view records from per-view lists (each None, or one entry per camera; ``found``: each view's
    :class:`Findings`)."""
    n = len(cameras)
    for what, per_view in (("images", images), ("valid", valid), ("masks", masks), ("measured_px", measured_px),
                           ("left_out", left_out), ("found", found)):
        if per_view is not None and len(per_view) != n:
            raise ValueError(f"{what}: {len(per_view)} entries for {n} views")

    def at(per_view, v):
        return per_view[v] if per_view is not None else None

    return [View(cam, at(images, v), at(valid, v), at(masks, v), at(found, v), at(measured_px, v), at(left_out, v))
            for v, cam in enumerate(cameras)]


@dataclass(kw_only=True)
class Scene:
    """Rays and observations of a BOS experiment.

    Attributes:
        box: the probe box (reconstruction grid).
        ambient: T0, n0 and the normalisation scale delta_thre.
        views: the V per-view records (:class:`View`: camera, images, valid pixels, mask, what was measured).
        origins: (V, 3) camera centres [mm].
        dirs: (N, 3) unit directions of every ray that crosses the box, grouped by view.
        eps: (N, 3) observed world-frame deflections [rad].
        pixel: (N,) flat pixel index (row * width + column) of each ray in its camera.
        view_start: (V + 1,) offsets of each view's rays.
        truth_T: (nx, ny, nz) true temperature [K] on ``box`` where known (synthetic scenes), else None.
        perpendicular_only: the observations are only the part of each deflection perpendicular to its ray, as
            measured through image displacements (their along-ray component is zero and means nothing); solvers
            then compare only that part. False for ideal sensing (full vectors).
        sensing: what realistic sensing saw and measured, for figures and scores
            (:class:`nerif.sensing.record.SensingRecord`), else None.
        heldout: the views kept out of training, as a scene of their own (same box and ambient), else None.
        sigma_prior: (a, b) interval of sigma the data say the field lies in, else None (the field's default).
        sigma_prior_from: the setting that gave ``sigma_prior``, as a user would edit it (a rig file's
            ``temperature_range_K``, ``data.sigma_prior``).
        cache_dir: where values derived from these data may be kept (``data.cache_dir``: the image term's
            photometric scale), else None.
        displacements: (N, 2) the image displacements measured for each ray [px of the full sensor] where the data
            were measured as displacements (captures, realistic sensing), else None (:attr:`displacement_px`
            derives them).
        observed: (N, 3) the observations in the unit the solvers fit, deflections of sigma: ``eps / scale``
            (derived, computed once).
    The per-view lists (``cameras``, ``images``, ``valid_images``, ``mask_images``, ``measured``) are read from
    ``views``.
    """

    box: ProbeBox
    ambient: Ambient
    views: list[View]
    origins: torch.Tensor
    dirs: torch.Tensor
    eps: torch.Tensor
    pixel: torch.Tensor
    view_start: torch.Tensor
    truth_T: Optional[np.ndarray] = None
    sensing: Optional[SensingRecord] = None
    perpendicular_only: bool = False
    heldout: Optional["Scene"] = None
    sigma_prior: Optional[tuple] = None
    sigma_prior_from: Optional[str] = None
    cache_dir: Optional[str] = None
    displacements: Optional[torch.Tensor] = None
    observed: torch.Tensor = field(init=False, repr=False)

    def __post_init__(self):
        self.observed = self.eps / self.scale

    @property
    def cameras(self) -> list[Camera]:
        return [v.camera for v in self.views]

    def _every(self, name: str) -> Optional[list]:
        """Each view's ``name``, or None where the views have none."""
        per_view = [getattr(v, name) for v in self.views]
        return per_view if any(x is not None for x in per_view) else None

    @property
    def images(self) -> Optional[list[ViewImages]]:
        return self._every("images")

    @property
    def valid_images(self) -> Optional[list[np.ndarray]]:
        return self._every("valid")

    @property
    def mask_images(self) -> Optional[list[np.ndarray]]:
        return self._every("mask")

    @property
    def findings(self) -> Optional[list[Findings]]:
        """What the measurement stage found in each view (:class:`Findings`); None where the data were not
        measured from images."""
        return [view.found for view in self.views] if self.views and self.views[0].found is not None else None

    def with_found(self, **per_view) -> "Scene":
        """The same scene with these measurement findings (a :class:`Findings` field -> list of one value per view)
        set in its views' records (made where they had none)."""
        for k, x in per_view.items():
            if len(x) != self.n_views:
                raise ValueError(f"{k}: {len(x)} values for {self.n_views} views")
        return replace(self, views=[replace(view, found=replace(view.found or Findings(),
                                                                **{k: x[v] for k, x in per_view.items()}))
                                    for v, view in enumerate(self.views)])

    @property
    def scale(self) -> float:
        """Radians of deflection per unit of sigma deflection (``ambient.delta_thre``; 1 for data in sigma)."""
        return self.ambient.delta_thre

    @property
    def ray_spacing_mm(self) -> float:
        """The distance [mm] between neighbouring rays at the probe centre (:func:`nerif.geometry.ray_spacing_mm`)."""
        return ray_spacing_mm(self.cameras, self.box)

    @property
    def n_views(self) -> int:
        return len(self.cameras)

    @cached_property
    def gain(self) -> torch.Tensor:
        """(N, 2, 3) float64: each ray's image displacement [px of the full sensor] per radian of deflection
        (:func:`nerif.sensing.displacement.displacement_matrix`), built once."""
        out = self.dirs.new_zeros(len(self.dirs), 2, 3, dtype=torch.float64)
        for v, cam in enumerate(self.cameras):
            sl = self.view_slice(v)
            out[sl] = displacement_matrix(self.dirs[sl].double(), cam.full_sensor)
        return out

    def to_displacement(self, eps: torch.Tensor, index: Optional[torch.Tensor] = None) -> torch.Tensor:
        """(R, 3) deflections [rad] of the rays ``index`` (default: all) -> (R, 2) image displacements [px of the
        full sensor]."""
        gain = self.gain if index is None else self.gain[index]
        return (gain @ eps.double()[..., None])[..., 0].to(eps.dtype)

    @cached_property
    def displacement_px(self) -> torch.Tensor:
        """(N, 2) the observed image displacements [px of the full sensor]: as measured, or those of ``eps``."""
        return self.displacements if self.displacements is not None else self.to_displacement(self.eps)

    def image_block(self) -> Optional[int]:
        """Image pixels a ray spans across (the ray grid's binning over the images' grid; the one place this ratio
        is taken): a whole number, the same for every view; None where the scene has no images or a view's rays are
        not a whole number of image pixels apart."""
        if self.images is None:
            return None
        blocks = {divmod(cam.binning, im.camera.binning) for cam, im in zip(self.cameras, self.images)}
        b, rest = next(iter(blocks))
        return b if len(blocks) == 1 and not rest and b >= 1 else None

    def lacks_image_model(self, min_block: int = 1, one_size: bool = False) -> str:
        """What the scene lacks for its images to be modelled (the image term, unified BOS, the held-out image
        residual: the one place this is asked), "" where nothing: its background images, or rays a whole number of
        image pixels apart (at least ``min_block``), the same for every view (and images of one size, where
        ``one_size``: the image term stacks them)."""
        if self.images is None:
            return "the background images, which these data do not have"
        b = self.image_block()
        sizes = len({im.reference.shape for im in self.images})
        if b is None or b < min_block or (one_size and sizes > 1):
            least = f" (at least {min_block})" if min_block > 1 else ""
            return (f"every view's rays a whole number{least} of image pixels apart, the same for all"
                    + (", on images of one size" if one_size else "") + f" (rays binned {self.cameras[0].binning}, "
                    f"images {self.images[0].camera.binning}): raise the binning (data.binning or rig.binning)")
        return ""

    def shake_px(self) -> torch.Tensor:
        """(V, 2) float64: each view's rigid image shift between the exposures the measurement stage found and took
        off its displacements [px of the full sensor] (zeros where none was measured). The images still hold it:
        a term that compares them adds it back."""
        shakes = [f.shake_px for f in self.findings] if self.findings else None
        return torch.as_tensor(shakes if shakes is not None else np.zeros((self.n_views, 2)), dtype=torch.float64,
                               device=self.dirs.device).reshape(self.n_views, 2)

    def unknown_image(self, view: int) -> Optional[np.ndarray]:
        """(height, width) bool: the pixels of ``view`` without a usable measurement, or None where every pixel
        has one."""
        return None if self.valid_images is None else ~np.asarray(self.valid_images[view], dtype=bool)

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
        return replace(self, views=[self.views[v] for v in vs], origins=self.origins[vs], dirs=self.dirs[idx],
                       eps=self.eps[idx], pixel=self.pixel[idx], view_start=starts, heldout=None, sensing=None,
                       displacements=self.displacements[idx] if self.displacements is not None else None)

    def split_views(self, heldout) -> "Scene":
        """The scene of every view but ``heldout``, with those as its ``heldout`` scene (none: every view)."""
        held = heldout_views(heldout, self.n_views)
        if not held:  # every view trains
            return replace(self, heldout=None)
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
                       displacements=self.displacements.to(device) if self.displacements is not None else None,
                       heldout=self.heldout.to(device) if self.heldout is not None else None,
                       views=[v.to(device) for v in self.views])


def _gathered(rays: tuple, images: list[np.ndarray], valid: list[np.ndarray], cameras: list[Camera],
              box: ProbeBox, measured: bool = False):
    """Per-pixel ``images`` (per view, (height, width, C)) at each ray of ``rays`` (origins, dirs, pixel,
    view_start), and the rays kept: those whose pixel is ``valid`` with finite values; one sentence for a view left
    with no ray (``measured``: only for a view with no ray through the box at all; one whose measurement left none
    is kept empty, for :mod:`nerif.data.diagnostics` to name and leave out). Returns (origins, dirs, values (N, C),
    pixel, view_start) of the kept rays."""
    origins, dirs, pixel, view_start = rays
    crossing = view_start.diff().tolist()
    device = dirs.device

    def per_ray(per_view, dtype):
        out = []
        for v, img in enumerate(per_view):
            img = np.asarray(img)
            flat = torch.as_tensor(img.reshape(img.shape[0] * img.shape[1], *img.shape[2:]), dtype=dtype, device=device)
            out.append(flat[pixel[view_start[v]:view_start[v + 1]]])
        return torch.cat(out)

    values, keep = per_ray(images, torch.float64), per_ray(valid, torch.bool)
    keep &= torch.isfinite(values).all(-1)
    dirs, values, pixel, view_start = keep_rays(dirs, values, pixel, view_start, keep)
    for v, n in enumerate(view_start.diff().tolist()):
        if n == 0 and (crossing[v] == 0 or not measured):
            raise ValueError(f"{cameras[v].name}: no pixel of its region of interest sees the probe box "
                             f"{box.extent_mm.tolist()} mm: check the region of interest, the pose and the probe box")
    return origins, dirs, values, pixel, view_start


def scene_from_images(box: ProbeBox, ambient: Ambient, cameras: list[Camera], eps_images: list[np.ndarray],
                      valid: list[np.ndarray], device="cpu", rays: Optional[tuple] = None,
                      masks: Optional[list[np.ndarray]] = None, **fields) -> Scene:
    """A scene of measured deflections: per view, the image pixels that are ``valid`` and whose ray crosses the box.

    Args:
        eps_images: per view, (height, width, 3) world-frame deflections [rad], as measured through image
            displacements; they are stored perpendicular to each ray (see :func:`perpendicular`).
        valid: per view, (height, width) bool: the region of interest and finite data.
        rays: :func:`nerif.geometry.rays_in_box` of ``box`` and ``cameras`` on ``device``, where the caller has
            them already (else computed here).
        masks: per view, (height, width) bool 2-D masks that came with the data, else None.
        fields: further :class:`Scene` fields (``heldout``, ``sensing``, ``truth_T``, ``sigma_prior``).
    Raises a clear error for a view with no valid pixel on the box.
    """
    rays = rays_in_box(box, cameras, device) if rays is None else rays
    origins, dirs, eps, pixel, view_start = _gathered(rays, eps_images, valid, cameras, box)
    eps = eps.float()
    known = [np.asarray(ok, dtype=bool) & np.isfinite(e).all(-1) for ok, e in zip(valid, eps_images)]
    return Scene(box=box, ambient=ambient, views=views_of(cameras, valid=known, masks=masks), origins=origins,
                 dirs=dirs, eps=perpendicular(eps, dirs), pixel=pixel, view_start=view_start, perpendicular_only=True,
                 **fields)


def scene_from_displacements(box: ProbeBox, ambient: Ambient, cameras: list[Camera], displacements: list[np.ndarray],
                             valid: list[np.ndarray], device="cpu", rays: Optional[tuple] = None,
                             images: Optional[list[ViewImages]] = None, found: Optional[list] = None,
                             left_out: Optional[list[np.ndarray]] = None, **fields) -> Scene:
    """A scene of measured image displacements (:class:`nerif.sensing.measurement.ViewMeasurement`): per view, the
    pixels that are ``valid`` and whose ray crosses the box, each ray's displacement kept (``Scene.displacements``)
    and turned into its deflection once.

    Args:
        displacements: per view, (height, width, 2) displacements [px of the full sensor] on the ray grid.
        valid: per view, (height, width) bool: the pixels with a usable measurement.
        images: per view, the background images the displacements were measured from (None: not kept).
        found: per view, what the measurement stage found (:class:`Findings`), or None.
        left_out: per view, (height, width) uint8 why each pixel was left out (:class:`View`), or None.
        rays, fields: as for :func:`scene_from_images`.
    """
    rays = rays_in_box(box, cameras, device) if rays is None else rays
    origins, dirs, u, pixel, view_start = _gathered(rays, displacements, valid, cameras, box, measured=True)
    eps = torch.cat([displacement_to_deflection(u[view_start[v]:view_start[v + 1]],
                                                dirs[view_start[v]:view_start[v + 1]].double(),
                                                cam.full_sensor) for v, cam in enumerate(cameras)])
    views = views_of(cameras, images, [np.asarray(ok, dtype=bool) for ok in valid], found=found,
                     measured_px=list(displacements) if left_out is not None else None, left_out=left_out)
    return Scene(box=box, ambient=ambient, views=views, origins=origins, dirs=dirs, eps=eps.float(), pixel=pixel,
                 view_start=view_start, perpendicular_only=True, displacements=u.float(), **fields)


def heldout_views(heldout, n_views: int, what: str = "the held-out views") -> list[int]:
    """Sorted distinct held-out view indices, checked: a list of whole numbers (``what`` names the setting in the
    sentence otherwise), within range and leaving a view to train on."""
    if not isinstance(heldout, (list, tuple)) or any(
            isinstance(v, bool) or not isinstance(v, (int, float)) or not float(v).is_integer() for v in heldout):
        example = f"[{heldout}]" if isinstance(heldout, int) and not isinstance(heldout, bool) else "[0, 4]"
        raise ValueError(f"{what}={heldout!r} must be a list of view indices, such as {example}")
    held = sorted({int(v) for v in heldout})
    if any(not 0 <= v < n_views for v in held):
        raise ValueError(f"{what} {held} must be within 0..{n_views - 1}")
    if len(held) >= n_views:
        raise ValueError(f"all {n_views} views are held out: at least one must be trained on")
    return held


def kept_pixels(cameras: list[Camera], pixel: torch.Tensor, view_start: torch.Tensor, keep: torch.Tensor) -> list:
    """Per view, (height, width) bool: False at the pixels of the rays ``keep`` (N,) leaves out (their measurement
    is unusable), True elsewhere."""
    out, keep, pixel = [], keep.cpu().numpy(), pixel.cpu().numpy()
    for v, cam in enumerate(cameras):
        sl = slice(int(view_start[v]), int(view_start[v + 1]))
        ok = np.ones(cam.height * cam.width, bool)
        ok[pixel[sl][~keep[sl]]] = False
        out.append(ok.reshape(cam.height, cam.width))
    return out


def keep_rays(dirs, eps, pixel, view_start, keep: torch.Tensor):
    """The rays where ``keep`` (N,) is True, with the view offsets recomputed."""
    counts = torch.bincount(view_index(view_start)[keep], minlength=len(view_start) - 1)
    starts = torch.cat([counts.new_zeros(1), counts.cumsum(0)])
    return dirs[keep], eps[keep], pixel[keep], starts


