"""Camera rays through the probe box: which pixels of which camera see it, stored concatenated by view.

Rays of all views are kept as one array with ``view_start`` offsets (V + 1,): view v owns rays
``view_start[v]:view_start[v + 1]``.
"""
from __future__ import annotations

import numpy as np
import torch

from nerif.geometry.box import ProbeBox
from nerif.geometry.camera import Camera


def rays_in_box(box: ProbeBox, cameras: list[Camera], device="cpu"):
    """Directions and pixel indices of the rays of each camera that cross the box.

    Raises a clear error for a camera that does not see the box at all.
    Returns: origins (V, 3), dirs (N, 3), pixel (N,), view_start (V + 1,).
    """
    dirs, pixels, starts = [], [], [0]
    corners = np.stack(np.meshgrid(*[[-h, h] for h in box.half_mm], indexing="ij"), -1).reshape(-1, 3)
    for cam in cameras:
        if np.all(np.abs(cam.position) < box.half_mm):
            raise ValueError(f"{cam.name} at {np.round(cam.position, 1)} mm is inside the probe box "
                             f"{box.extent_mm.tolist()} mm: check the camera distance and the probe box")
        far = float(((corners - cam.position) @ np.asarray(cam.rotation)[:, 2]).max())
        if not cam.background_mm > far:
            raise ValueError(f"{cam.name}: its background, {cam.background_mm:g} mm away, is not behind the probe box "
                             f"(whose far side is {far:.0f} mm away): check the background distance")
        d = cam.pixel_directions(torch.float64).to(device)
        o = torch.as_tensor(cam.position, dtype=torch.float64, device=device).expand_as(d)
        hit = box.intersect(o, d)[2]
        if not hit.any():
            raise ValueError(f"{cam.name} at {np.round(cam.position, 1)} mm does not see the probe box "
                             f"{box.extent_mm.tolist()} mm: check the rig geometry and the probe box")
        idx = hit.nonzero()[:, 0]
        dirs.append(d[idx].float())
        pixels.append(idx)
        starts.append(starts[-1] + len(idx))
    origins = torch.tensor(np.stack([c.position for c in cameras]), dtype=torch.float32, device=device)
    return origins, torch.cat(dirs), torch.cat(pixels), torch.tensor(starts, device=device)


def outside_the_box(cameras: list[Camera], pixel: torch.Tensor, view_start: torch.Tensor) -> list[np.ndarray]:
    """Per view, (height, width) bool: the pixels whose ray misses the probe box (no flame deflects them), from the
    rays that cross it (:func:`rays_in_box`'s ``pixel`` (N,) and ``view_start`` (V + 1,))."""
    pixel, starts = pixel.cpu().numpy(), view_start.cpu().numpy()
    out = []
    for v, cam in enumerate(cameras):
        free = np.ones(cam.height * cam.width, bool)
        free[pixel[starts[v]:starts[v + 1]]] = False
        out.append(free.reshape(cam.height, cam.width))
    return out


def view_index(view_start: torch.Tensor) -> torch.Tensor:
    """(V + 1,) view offsets -> (N,) view of every ray."""
    return torch.repeat_interleave(torch.arange(len(view_start) - 1, device=view_start.device), view_start.diff())


def pixels_per_voxel(cameras: list[Camera], box: ProbeBox) -> float:
    """The median over the cameras of the sensor pixels one voxel of ``box`` spans across at the probe centre
    (cameras that do not face it left out; 0 where none does)."""
    scale = [cam.pixels_per_mm(np.zeros(3)) for cam in cameras]
    scale = [s for s in scale if np.isfinite(s) and s > 0]
    return float(np.median(scale)) * box.voxel_mm if scale else 0.0


def ray_spacing_mm(cameras: list[Camera], box: ProbeBox) -> float:
    """The distance [mm] between neighbouring rays at the probe centre: a voxel of ``box`` over the pixels of
    ``cameras`` as the rays read them (binned) one voxel spans there (:func:`pixels_per_voxel`); one voxel where no
    camera faces the probe."""
    per_voxel = pixels_per_voxel(cameras, box)
    return float(box.voxel_mm) / per_voxel if per_voxel > 0 else float(box.voxel_mm)


def ray_binning(cameras: list[Camera], box: ProbeBox) -> int:
    """The binning that puts about one ray per voxel across at the probe centre: the common divisor b of every
    camera's width and height nearest (in ratio) to :func:`pixels_per_voxel`. Finer rays than the voxels only
    repeat what their neighbours measure; coarser ones average over several voxels (on the shared bunsen capture
    8 x 8 pixels span two voxels and give a sigma error of 0.183, 4 x 4 give 0.122)."""
    per_voxel = max(pixels_per_voxel(cameras, box), 1e-9)
    common = int(np.gcd.reduce([int(n) for cam in cameras for n in (cam.width, cam.height)]))
    divisors = [b for b in range(1, common + 1) if common % b == 0]
    return min(divisors, key=lambda b: abs(np.log(b / per_voxel)))
