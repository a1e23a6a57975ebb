"""An opaque burner tube in the views of the realistic chain: a vertical cylinder on the probe box's axis (``x = z
= 0``, ``y`` vertical), closed at its top. A pixel whose ray meets it sees the tube, dark and without texture, in
both exposures; its ray is blocked (a capture's measurement stage must find it unknown, not empty)."""
from __future__ import annotations

import numpy as np
import torch

from nerif.geometry import Camera

DARK = 0.08  # the tube's brightness, a share of full scale (about 20 DN of 255)


def burner_pixels(camera: Camera, radius_mm: float, top_mm: float) -> np.ndarray:
    """(H, W) bool: the pixels of ``camera`` whose chief ray meets a tube of ``radius_mm`` on the axis whose top is
    at ``y = top_mm`` (world frame [mm]) and which runs down past the view."""
    d = camera.pixel_directions(torch.float64).cpu().numpy()
    o = np.asarray(camera.position, dtype=np.float64)
    a = d[:, 0] ** 2 + d[:, 2] ** 2
    b = 2.0 * (o[0] * d[:, 0] + o[2] * d[:, 2])
    c = o[0] ** 2 + o[2] ** 2 - radius_mm**2
    disc = b * b - 4.0 * a * c
    hit = (disc >= 0) & (a > 0)
    root = np.sqrt(np.where(hit, disc, 0.0))
    safe = np.where(a > 0, a, 1.0)
    y_in, y_out = (o[1] + (-b - root) / (2 * safe) * d[:, 1], o[1] + (-b + root) / (2 * safe) * d[:, 1])
    hit &= np.minimum(y_in, y_out) <= top_mm  # below the top where it crosses the tube's wall (or its top cap)
    return hit.reshape(camera.height, camera.width)
