"""Finite-aperture optics of a BOS camera focused on its background.

Lengths in mm. ``Z_B`` is the camera-to-background distance along the axis, ``Z_A`` the camera-to-probe
distance (the probe centre is the world origin), ``Z_D = Z_B - Z_A``; ``M = s_i / Z_B`` is the magnification
of the background (``s_i`` the image distance).
"""
from __future__ import annotations

import numpy as np
import torch

from nerif.geometry import Camera


def probe_distance_mm(camera: Camera) -> float:
    """Z_A: distance from the camera to the probe centre (world origin) along the optical axis [mm]."""
    return float(-np.asarray(camera.position) @ camera.rotation[:, 2])


def magnification(camera: Camera) -> float:
    """M = s_i / Z_B, the magnification of the (in-focus) background."""
    return camera.image_distance_mm / camera.background_mm


def circle_of_confusion(camera: Camera, wavelength_um: float = 0.5) -> dict:
    """Blur diameters on the sensor [mm] of a point at the probe centre, for a camera focused on the background.

    ``d_geo = (f / N) * M * Z_D / Z_A`` (geometric defocus: the aperture cone through the probe point covers a
    disc of diameter ``(f / N) Z_D / Z_A`` on the background), ``d_diff = 2.44 lambda N (1 + M)`` (Airy disc),
    ``d = sqrt(d_geo^2 + d_diff^2)``. Divide by ``camera.pitch_mm`` for pixels.
    """
    za = probe_distance_mm(camera)
    m = magnification(camera)
    d_geo = camera.focal_mm / camera.f_number * m * (camera.background_mm - za) / za
    d_diff = 2.44 * wavelength_um * 1e-3 * camera.f_number * (1 + m)
    return {"d_geo_mm": d_geo, "d_diff_mm": d_diff, "d_mm": float(np.hypot(d_geo, d_diff))}


def aperture_points(n: int, diameter_mm: float) -> np.ndarray:
    """``n`` points spread evenly over the lens aperture (Vogel's sunflower spiral), (n, 2) [mm] in the lens
    plane as (right, down); one point is the aperture centre (a pinhole)."""
    if n < 1:
        raise ValueError(f"a pixel needs at least one ray through the aperture, got {n}")
    if n == 1:
        return np.zeros((1, 2))
    k = np.arange(n)
    r = 0.5 * diameter_mm * np.sqrt((k + 0.5) / n)
    phi = k * np.pi * (3 - np.sqrt(5))
    return np.stack([r * np.cos(phi), r * np.sin(phi)], -1)


def aperture_rays(camera: Camera, dirs: torch.Tensor, n_rays: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays from points across the aperture to the background point each pixel is focused on.

    Args:
        dirs: (P, 3) chief-ray directions of P pixels (unit, world frame).
        n_rays: rays per pixel.
    Returns:
        origins, directions: (P, n_rays, 3) [mm] and unit vectors.
    """
    R = torch.as_tensor(camera.rotation, dtype=dirs.dtype, device=dirs.device)
    c = torch.as_tensor(camera.position, dtype=dirs.dtype, device=dirs.device)
    focus = c + dirs * (camera.background_mm / (dirs @ R[:, 2]))[:, None]  # (P, 3) on the background plane
    a = torch.as_tensor(aperture_points(n_rays, camera.focal_mm / camera.f_number), dtype=dirs.dtype, device=dirs.device)
    origins = (c + a @ R[:, :2].T).expand(len(dirs), -1, -1)  # (P, n, 3)
    d = focus[:, None] - origins
    return origins, d / d.norm(dim=-1, keepdim=True)
