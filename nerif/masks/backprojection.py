"""The paper's two-level masking: 2-D masks from the observed deflections, 3-D mask by back-projection."""
from __future__ import annotations

import warnings

import cv2
import numpy as np
import torch

from nerif.geometry import ProbeBox, sample_volume
from nerif.masks.base import MASKS, Masks


def deflection_masks(scene, threshold: float = 0.001, radius_px: int = 2) -> list[np.ndarray]:
    """Per view: ``|eps|^2 / max |eps|^2 > threshold``, dilated by a disc of ``radius_px`` pixels, holes
    filled (OpenCV). The fill matters: rays through the core of a symmetric flame are barely deflected,
    so the thresholded magnitude alone is hollow where the flame is hottest.

    Returns (height, width) bool images. A view with no deflection above the threshold gets an empty mask
    and a warning naming it.
    """
    out = []
    for v, cam in enumerate(scene.cameras):
        mag2 = (scene.eps[scene.view_slice(v)].double() ** 2).sum(-1).cpu().numpy()
        peak = mag2.max() if mag2.size else 0.0
        norm = mag2 / peak if peak > 0 and np.isfinite(peak) else np.zeros_like(mag2)
        m = (scene.view_image(v, norm) > threshold).astype(np.uint8)
        if radius_px > 0:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
            m = cv2.dilate(m, disc)
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        m = cv2.drawContours(m, contours, -1, 1, thickness=cv2.FILLED)
        if not m.any():
            warnings.warn(f"{cam.name}: no deflection above the mask threshold {threshold}; its 2-D mask is empty",
                          stacklevel=2)
        out.append(m.astype(bool))
    return out


def masks_2d(scene, threshold: float, radius_px: int) -> list[np.ndarray]:
    """The 2-D masks that came with the data, else :func:`deflection_masks`."""
    if scene.mask_images is not None:
        return [np.asarray(m, dtype=bool) for m in scene.mask_images]
    return deflection_masks(scene, threshold, radius_px)


def back_project(box: ProbeBox, cameras, images: list[np.ndarray], n_cameras_required: int | None = None) -> np.ndarray:
    """3-D mask: voxels whose centre projects inside the 2-D masks of at least ``n_cameras_required`` views
    (default: all, the visual hull). Returns (nx, ny, nz) bool."""
    need = len(cameras) if n_cameras_required is None else int(n_cameras_required)
    if not 1 <= need <= len(cameras):
        raise ValueError(f"n_cameras_required must be within 1..{len(cameras)}, got {need}")
    centres = box.centres().reshape(-1, 3)
    count = np.zeros(len(centres), dtype=np.int32)
    for cam, img in zip(cameras, images):
        uv = np.floor(cam.project(centres)).astype(np.int64)
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] < cam.height)
        hit = np.zeros(len(centres), dtype=bool)
        hit[ok] = img[uv[ok, 1], uv[ok, 0]]
        count += hit
    return (count >= need).reshape(box.shape)


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
def mask_2d(scene, threshold: float = 0.001, radius_px: int = 2) -> Masks:
    """Training rays drawn inside each view's 2-D mask."""
    images = masks_2d(scene, threshold, radius_px)
    return Masks(images=images, inside=_inside(scene, images))


@MASKS.register("3d")
def mask_3d(scene, threshold: float = 0.001, radius_px: int = 2, n_cameras_required: int | None = None) -> Masks:
    """2-D ray sampling plus the back-projected 3-D mask gating the field."""
    images = masks_2d(scene, threshold, radius_px)
    volume = back_project(scene.box, scene.cameras, images, n_cameras_required)
    if not volume.any():
        raise ValueError("the 3-D mask is empty: no voxel lies inside enough 2-D masks (lower mask.threshold, "
                         "raise mask.radius_px or lower mask.n_cameras_required)")
    return Masks(images=images, inside=_inside(scene, images), gate=MaskGate(volume, scene.box, scene.dirs.device),
                 volume=volume)
