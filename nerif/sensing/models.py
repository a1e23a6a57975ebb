"""Sensing models: what a rig measures of a synthetic field (``data.sensing``).

Every model is ``fn(delta, box, cameras, dirs, pixel, view_start, step_mm, rig_binning, cache_dir=None, **sensor)
-> (observed, record or None)``: what the rig observes of a field ``delta`` (nx, ny, nz) on ``box``, the training
rays' deflections (N, 3) [rad] (see :class:`nerif.data.scene.Scene`), or where the model measures them from images
its views' measurements (:class:`nerif.sensing.record.MeasuredViews`); and what only the model knows (its truth,
:class:`nerif.sensing.record.SensingRecord`) for figures and scores. Registered in :data:`SENSING`: ``ideal`` and
``perpendicular`` here, ``realistic`` in :mod:`nerif.sensing.realistic`.
"""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch

from nerif.geometry import Camera, ProbeBox, view_index
from nerif.registry import Registry
from nerif.renderers.deflection import perpendicular
from nerif.renderers.voxel import voxel_deflection

SENSING = Registry("sensing", package="nerif.sensing")


@SENSING.register("ideal")
def ideal(delta: torch.Tensor, box: ProbeBox, cameras: list[Camera], dirs: torch.Tensor, pixel: torch.Tensor,
          view_start: torch.Tensor, step_mm: Optional[float], rig_binning: int, cache_dir=None, **sensor):
    """Thin chief rays, noise-free: the full deflection vectors, including the along-ray component that no
    camera measures (the ``sensor`` parameters do not apply)."""
    origins = torch.tensor(np.stack([c.position for c in cameras]), dtype=dirs.dtype, device=dirs.device)
    o = origins[view_index(view_start.to(dirs.device))]
    return voxel_deflection(delta, box, o, dirs, step_mm), None


@SENSING.register("perpendicular")
def ideal_perpendicular(delta: torch.Tensor, box: ProbeBox, cameras: list[Camera], dirs: torch.Tensor,
                        pixel: torch.Tensor, view_start: torch.Tensor, step_mm: Optional[float], rig_binning: int,
                        cache_dir=None, **sensor):
    """Thin chief rays, noise-free, but only what a camera can measure: the part of each deflection
    perpendicular to its ray (a perfect displacement measurement; realistic sensing without blur or noise)."""
    eps, _ = ideal(delta, box, cameras, dirs, pixel, view_start, step_mm, rig_binning)
    return perpendicular(eps, dirs), None
