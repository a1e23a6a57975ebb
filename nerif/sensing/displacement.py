"""Deflection <-> image displacement through the rig geometry.

A ray with direction ``d`` is deflected by ``eps`` (rad, world frame, ``eps . d = 0`` for a straight ray
through a bounded field) at the probe centre. It reaches the background plane (normal ``f``, the camera axis,
``Z_D`` behind the probe centre) shifted by ``Delta = L (eps - d (f . eps) / (f . d))`` with ``L = Z_D / (f . d)``;
the camera sees that shift as ``u = s_i / (Z_B p) (r . Delta, w . Delta)`` pixels (column, row), with ``r, w``
its right and down axes, ``s_i`` the image distance, ``p`` the pixel pitch (rows scaled by ``fy / fx`` where a
calibration gives them their own focal length). The image at pixel ``x`` shows the background at ``x + u``. Both
maps are linear; the inverse uses ``eps . d = 0`` as the third equation. A lens's distortion changes the local
scale of its image by ``1 + 3 k1 r^2`` at normalised radius ``r``: under 1.5 % at the corners of the lenses
calibrated so far, below the optical flow's error, so displacements are taken as on the undistorted grid.
"""
from __future__ import annotations

import torch

from nerif.geometry import Camera
from nerif.sensing.optics import probe_distance_mm


def displacement_matrix(dirs: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(N, 3) unit ray directions -> (N, 2, 3) matrices A with ``u [px] = A eps [rad]``."""
    R = torch.as_tensor(camera.rotation, dtype=dirs.dtype, device=dirs.device)
    right, down, f = R[:, 0], R[:, 1], R[:, 2]
    fd = dirs @ f  # (N,)
    L = (camera.background_mm - probe_distance_mm(camera)) / fd
    k = camera.image_distance_mm / (camera.background_mm * camera.pitch_mm)
    rows = [axis[None, :] - (dirs @ axis)[:, None] * f[None, :] / fd[:, None] for axis in (right, down)]
    if camera.aspect != 1.0:  # a calibrated camera: rows have their own focal length
        rows[1] = rows[1] * camera.aspect
    return (k * L)[:, None, None] * torch.stack(rows, 1)


def deflection_to_displacement(eps: torch.Tensor, dirs: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(N, 3) deflections [rad] of rays along ``dirs`` -> (N, 2) image displacements [px] (column, row)."""
    A = displacement_matrix(dirs.double(), camera)
    return (A @ eps.double()[..., None])[..., 0].to(eps.dtype)


def displacement_to_deflection(u: torch.Tensor, dirs: torch.Tensor, camera: Camera) -> torch.Tensor:
    """(N, 2) image displacements [px] -> (N, 3) deflections [rad] perpendicular to ``dirs``."""
    d = dirs.double()
    M = torch.cat([displacement_matrix(d, camera), d[:, None, :]], 1)  # (N, 3, 3)
    rhs = torch.cat([u.double(), torch.zeros_like(u[:, :1], dtype=torch.float64)], -1)
    return torch.linalg.solve(M, rhs[..., None])[..., 0].to(u.dtype)

