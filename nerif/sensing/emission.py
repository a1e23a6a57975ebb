"""The flame's own light as a camera focused on the background records it: the flame's emission integrated along
each pixel's ray, seen out of focus (the lens is focused on the background, so the flame at the probe is blurred by
the circle of confusion, :func:`nerif.sensing.optics.circle_of_confusion`). Its structure at that scale is what
throws an optical flow normalised over a wider window off (issue 37)."""
from __future__ import annotations

from typing import Optional

import cv2
import numpy as np
import torch

from nerif.geometry import Camera, ProbeBox
from nerif.renderers.voxel import line_integral

RAYS_PER_BLUR = 1.0  # the light is traced this many rays a blur width (sigma) across, then interpolated


def flame_light(delta: torch.Tensor, box: ProbeBox, camera: Camera, blur_diameter_px: float,
                step_mm: Optional[float] = None) -> np.ndarray:
    """(H, W) float32 the flame's light on ``camera``'s images, its brightest pixel 1: the line integral of
    ``|delta|`` (nx, ny, nz) along each pixel's chief ray (a proxy for the emission of the hot gas), blurred by a
    Gaussian of sigma ``blur_diameter_px / 4`` (a uniform disc's of that diameter [px of these images]). The rays are
    traced on a grid :data:`RAYS_PER_BLUR` rays a sigma across (every pixel where the blur is under a pixel wide)
    and bilinearly interpolated to the images' grid."""
    sigma = blur_diameter_px / 4.0
    H, W = camera.height, camera.width
    stride = max(1, int(sigma / RAYS_PER_BLUR))
    while stride > 1 and (H % stride or W % stride):
        stride -= 1
    cam = camera.binned(stride) if stride > 1 else camera
    dirs = cam.pixel_directions(torch.float64).to(delta.device)
    origins = torch.as_tensor(cam.position, dtype=torch.float64, device=delta.device).expand(len(dirs), 3)
    light = line_integral(delta.abs()[None].double(), box, origins, dirs, step_mm)[:, 0]
    light = light.reshape(cam.height, cam.width).cpu().numpy().astype(np.float32)
    if stride > 1:
        light = cv2.resize(light, (W, H), interpolation=cv2.INTER_LINEAR)
    if sigma >= 0.3:
        light = cv2.GaussianBlur(light, (0, 0), sigma)
    return light / max(float(light.max()), 1e-30)
