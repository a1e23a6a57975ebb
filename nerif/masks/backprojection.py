"""The paper's two-level masking: 2-D masks from the observed deflections, 3-D mask by back-projection."""
from __future__ import annotations

import warnings

import cv2
import numpy as np
import torch

from nerif.geometry import FACES, ProbeBox, box_faces, face_names, sample_volume
from nerif.masks.base import MASKS, Masks


def fill_holes(mask: np.ndarray, region: np.ndarray) -> np.ndarray:
    """Fill the holes of a 2-D mask inside the region the view's rays cover (the probe box's image).

    A hole is a connected part of ``region`` outside ``mask`` (4-connected) that touches the edge of the region on
    at most one side: top, bottom, left or right, whichever side of the region's bounding rectangle the contact
    pixel is nearest to (the box's image has slanted, stair-stepped edges). Enclosed holes are the barely deflected
    core of a symmetric flame; the one-sided ones are the same core where the probe box cuts the flame: the cut
    opens the core to one edge of the box's image (a notch), and a notch left open would carve hot gas out of the
    visual hull. Background that reaches two sides or more (around a flame, between two flames) stays ambient.

    Args:
        mask, region: (height, width) bool. Returns: (height, width) bool, ``mask`` with its holes filled.
    """
    background = region & ~mask
    if not background.any():
        return mask.copy()
    n, labels = cv2.connectedComponents(background.astype(np.uint8), connectivity=4)
    outside = ~np.pad(region, 1)  # beyond the image counts as outside the region
    H, W = region.shape
    touching = np.zeros((H, W), bool)
    for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        touching |= outside[1 + dr:1 + dr + H, 1 + dc:1 + dc + W]
    r, c = np.nonzero(background & touching)
    rows, cols = np.nonzero(region)
    side = np.argmin(np.stack([r - rows.min(), rows.max() - r, c - cols.min(), cols.max() - c]), axis=0)
    sides = np.zeros((n, 4), bool)
    sides[labels[r, c], side] = True
    hole = sides.sum(1) <= 1
    hole[0] = False  # label 0: not background
    return mask | (hole[labels] & background)


def noise_level(eps_image: np.ndarray) -> float:
    """Robust standard deviation of the noise in a (height, width, C) image of deflections (NaN where there is no
    ray), from second differences along rows: they cancel the smooth field up to its curvature, while independent
    noise adds sqrt(6) times its deviation (median absolute deviation, pooled over the components). On Phantom 5's
    clean views it gives 0.3 % of the peak deflection; with Gaussian noise of 10 % and 20 % of the RMS deflection
    it recovers the noise within 10 %."""
    d = eps_image[:, 2:] - 2 * eps_image[:, 1:-1] + eps_image[:, :-2]
    d = np.abs(d[np.isfinite(d)])
    return float(1.4826 * np.median(d) / np.sqrt(6.0)) if d.size else 0.0


def box_image(scene, view: int) -> np.ndarray:
    """(height, width) bool: the pixels of ``view`` whose rays cross the probe box (the box's image)."""
    return scene.view_image(view, np.ones(len(scene.dirs[scene.view_slice(view)])), 0.0) > 0


def dilation_radius_px(camera, radius_px: int, radius_mm: float) -> int:
    """The 2-D masks' dilation radius in ``camera``'s pixels: at least ``radius_px`` pixels and at least
    ``radius_mm`` at the probe box's centre. A radius in pixels alone shrinks in the world as the images get finer:
    where the box cuts a flame, the rays along that edge of the box's image cross it over a short chord and deflect
    little, and a strip of them below the threshold then joins the flame's open core to the background on two sides,
    so that :func:`fill_holes` no longer fills it and the visual hull carves the flame (Phantom 5 at 1 mm, 2 x 2
    binning: 36 % of the flame carved away with 2 px, none with 2.3 mm)."""
    scale = camera.pixels_per_mm(np.zeros(3))  # the probe box is centred on the world origin
    return max(int(radius_px), int(round(radius_mm * scale)))


def deflection_masks(scene, threshold: float = 0.001, radius_px: int = 2, noise_sigmas: float = 4.0,
                     radius_mm: float = 2.3) -> list[np.ndarray]:
    """Per view: ``|eps|^2 / max |eps|^2 > threshold`` and ``|eps| > noise_sigmas`` times the view's noise level
    (:func:`noise_level` per component, so ``|eps|^2 > 3 noise_sigmas^2 sigma_n^2``: on noisy data the relative
    threshold alone would take every pixel), dilated by a disc of :func:`dilation_radius_px` pixels, holes filled
    (:func:`fill_holes`). The fill matters: rays through the core of a symmetric flame are barely deflected, so the
    thresholded magnitude alone is hollow where the flame is hottest, and open to the edge where the box cuts it.

    Returns (height, width) bool images. A view with no deflection above the threshold gets an empty mask;
    one warning names every such view.
    """
    out, empty = [], []
    for v, cam in enumerate(scene.cameras):
        eps = scene.eps[scene.view_slice(v)].double().cpu().numpy()
        mag2 = (eps**2).sum(-1)
        peak = mag2.max() if mag2.size else 0.0
        floor = 3.0 * (noise_sigmas * noise_level(scene.view_image(v, eps, np.nan))) ** 2
        signal = peak > 0 and np.isfinite(peak)
        keep = (mag2 > threshold * peak) & (mag2 > floor) if signal else np.zeros(len(eps), bool)
        m = (scene.view_image(v, keep.astype(np.float64)) > 0).astype(np.uint8)
        r = dilation_radius_px(cam, radius_px, radius_mm)
        if r > 0:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
            m = cv2.dilate(m, disc)
        m = fill_holes(m.astype(bool), box_image(scene, v))
        if not m.any():
            empty.append(cam.name)
        out.append(m)
    if empty:
        warnings.warn(f"{', '.join(empty)}: no deflection above the mask threshold {threshold}; "
                      f"{'its 2-D mask is' if len(empty) == 1 else 'their 2-D masks are'} empty", stacklevel=2)
    return out


def masks_2d(scene, threshold: float = 0.001, radius_px: int = 2, noise_sigmas: float = 4.0,
             radius_mm: float = 2.3) -> list[np.ndarray]:
    """:func:`deflection_masks`, joined with the 2-D masks that came with the data where there are some.

    A mask that came with the data may leave out rays that are clearly deflected: the paper's Phantom 1 masks
    leave out the rows at the top and bottom of the box's image, where the flame and the fuel jet cross the box
    (3 % of the deflection energy, at 20 % of the RMS deflection inside). Back-projected alone, they carve the
    flame at those faces: a novel view's held-out error was 0.89 with ``mask=3d`` against 0.43 with ``mask=2d``.
    """
    ours = deflection_masks(scene, threshold, radius_px, noise_sigmas, radius_mm)
    if scene.mask_images is None:
        return ours
    out = []
    for v, m in enumerate(ours):
        out.append(fill_holes(np.asarray(scene.mask_images[v], dtype=bool) | m, box_image(scene, v)))
    return out


def back_project(box: ProbeBox, cameras, images: list[np.ndarray], n_cameras_required: int | None = None,
                 unknown: list | None = None) -> np.ndarray:
    """3-D mask: voxels whose centre projects inside the 2-D masks of at least ``n_cameras_required`` views
    (default: all, the visual hull). ``unknown``: per view, (height, width) bool pixels without a measurement, or
    None: a voxel that projects onto one is not carved by that view (no measurement says it is ambient).
    Returns (nx, ny, nz) bool."""
    need = len(cameras) if n_cameras_required is None else int(n_cameras_required)
    if not 1 <= need <= len(cameras):
        raise ValueError(f"n_cameras_required must be within 1..{len(cameras)}, got {need}")
    if unknown is not None:
        images = [np.asarray(img, dtype=bool) | u if u is not None else img for img, u in zip(images, unknown)]
    return views_seeing(box, cameras, images) >= need


def views_seeing(box: ProbeBox, cameras, images: list[np.ndarray]) -> np.ndarray:
    """(nx, ny, nz) int: for each voxel, the number of views whose ``images`` (per view, (height, width) bool) hold
    the pixel its centre projects to."""
    centres = box.centres().reshape(-1, 3)
    count = np.zeros(len(centres), dtype=np.int32)
    for cam, img in zip(cameras, images):
        uv = np.floor(cam.project(centres)).astype(np.int64)
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        hit = np.zeros(len(centres), dtype=bool)
        hit[ok] = np.asarray(img, dtype=bool)[uv[ok, 1], uv[ok, 0]]
        count += hit
    return count.reshape(box.shape)


def unknown_images(scene) -> list:
    """Per view, (height, width) bool: the pixels without a usable measurement (:meth:`Scene.unknown_image`), or
    None for a view where every pixel has one."""
    return [scene.unknown_image(v) for v in range(scene.n_views)]


def crossed_faces(hull: np.ndarray, min_cover: float) -> list[str]:
    """The faces of the probe box the flame crosses, as the data show them: faces whose voxels the visual hull
    ``hull`` (nx, ny, nz) covers over more than ``min_cover`` of the face's area. Measured on the default scenes
    (12 views, 2 mm voxels): Phantom 5's y and z faces 0.36-0.57, the axisymmetric flame's top 0.46, the
    turbulent plume's top and bottom 0.81 and 0.29; ambient faces 0 (Gaussian blob, Phantom 5's x faces) to 0.03
    (the plume's lateral faces, which its widening envelope nearly reaches)."""
    out = []
    for axis, side in box_faces(FACES):
        if np.take(hull, 0 if side < 0 else -1, axis=axis).mean() > min_cover:
            out += face_names([(axis, side)])
    return out


def ambient_faces(setting, scene, masks: Masks, min_cover: float, fallback) -> tuple[list[str], list[str]]:
    """The faces held at ambient (sigma = 0) and the faces the flame crosses.

    Args:
        setting: ``auto`` (every face the flame does not cross; ``fallback`` when the hull covers every face, as
            masks inflated by noise or by the smoothing of optical flow do: then the data do not tell) or a list
            of face names (as given).
        masks: the run's masks: their 3-D mask, else the back-projection of their 2-D masks, else (``mask=none``)
            the visual hull of :func:`deflection_masks` with its defaults tells which faces the flame crosses.
    Returns: (ambient face names, crossed face names).
    """
    hull = masks.volume
    if hull is None:
        images = masks.images
        if images is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # an empty view is reported by the masks that use it
                images = masks_2d(scene)
        hull = back_project(scene.box, scene.cameras, images, unknown=unknown_images(scene))
    crossed = crossed_faces(hull, min_cover)
    if setting == "auto":
        ambient = [f for f in FACES if f not in crossed]
        return (ambient or face_names(box_faces(fallback))), crossed
    return face_names(box_faces(setting)), crossed


class MaskGate:
    """Continuous (trilinear) 3-D mask: (N, 3) [mm] -> (N,) in [0, 1]."""

    def __init__(self, volume: np.ndarray, box: ProbeBox, device="cpu"):
        self.box = box
        self.volume = torch.as_tensor(volume, dtype=torch.float32, device=device)

    def __call__(self, p: torch.Tensor) -> torch.Tensor:
        return sample_volume(self.volume, self.box, p, padding="border")


def _inside(scene, images) -> list[torch.Tensor]:
    inside = []
    for v, img in enumerate(images):
        sl = scene.view_slice(v)
        flat = torch.as_tensor(img.reshape(-1), device=scene.pixel.device)
        idx = torch.arange(sl.start, sl.stop, device=scene.pixel.device)[flat[scene.pixel[sl]]]
        inside.append(idx)
    return inside


@MASKS.register("2d")
def mask_2d(scene, threshold: float = 0.001, radius_px: int = 2, noise_sigmas: float = 4.0,
            radius_mm: float = 2.3) -> Masks:
    """Training rays drawn inside each view's 2-D mask."""
    images = masks_2d(scene, threshold, radius_px, noise_sigmas, radius_mm)
    return Masks(images=images, inside=_inside(scene, images))


@MASKS.register("3d")
def mask_3d(scene, threshold: float = 0.001, radius_px: int = 2, noise_sigmas: float = 4.0,
            radius_mm: float = 2.3, n_cameras_required: int | None = None) -> Masks:
    """2-D ray sampling plus the back-projected 3-D mask gating the field. Views whose 2-D mask is empty (no
    signal: a camera that failed, already warned about) are left out of the back-projection, which would
    otherwise carve everything away."""
    images = masks_2d(scene, threshold, radius_px, noise_sigmas, radius_mm)
    seeing = [v for v, m in enumerate(images) if m.any()]
    need = None if n_cameras_required is None else max(1, int(n_cameras_required) - (len(images) - len(seeing)))
    unknown = unknown_images(scene)
    volume = back_project(scene.box, [scene.cameras[v] for v in seeing], [images[v] for v in seeing], need,
                          [unknown[v] for v in seeing]) if seeing else np.zeros(scene.box.shape, bool)
    if not volume.any():
        raise ValueError("the 3-D mask is empty: no voxel lies inside enough 2-D masks (lower mask.threshold, "
                         "raise mask.radius_px / mask.radius_mm or lower mask.n_cameras_required)")
    return Masks(images=images, inside=_inside(scene, images), gate=MaskGate(volume, scene.box, scene.dirs.device),
                 volume=volume)
