"""The measurement stage of one view: its distorted and reference background images in; the displacements on the
ray grid, their validity per pixel and what was found out. A capture (:mod:`nerif.data.capture`) and the
realistic chain (:mod:`nerif.sensing.realistic`) both measure through it, so that every synthetic benchmark runs
each step a real capture goes through. It is the one place the optical flow (:data:`nerif.sensing.flow.FLOW`)
runs; every step a view's images need before reconstruction belongs here.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from nerif.sensing.flow import FLOW
from nerif.sensing.imaging import resample

log = logging.getLogger(__name__)


@dataclass
class ViewMeasurement:
    """What one view's images say.

    Attributes:
        displacement: (h, w, 2) float32 image displacements [px of the full sensor] (column, row) on the ray grid,
            each a block mean of the flow's; NaN where ``valid`` is False.
        valid: (h, w) bool: pixels with a usable measurement. Any other pixel is unknown: it carves no visual hull,
            counts as no ambient and enters no loss and no score.
        found: what was found (numbers, for ``metrics.json`` and the log): ``displacement_max_px``,
            ``valid_fraction``.
        flow: (H, W, 2) the flow itself on the images' grid [px of that grid], kept where asked for figures, else
            None.
    """

    displacement: np.ndarray
    valid: np.ndarray
    found: dict = field(default_factory=dict)
    flow: Optional[np.ndarray] = None


def measure_view(distorted: np.ndarray, reference: np.ndarray, flow: dict, grid_px: tuple[int, int],
                 image_binning: int = 1, region: Optional[np.ndarray] = None, name: str = "",
                 keep_flow: bool = False) -> ViewMeasurement:
    """Measure one view.

    Args:
        distorted, reference: (H, W) float images in [0, 1] on the images' grid, ``image_binning`` sensor pixels
            a pixel across (1: the full sensor).
        flow: a :data:`FLOW` config. grid_px: (height, width) of the ray grid (a whole number of image pixels a
            ray, or the images' grid resampled).
        region: (height, width) bool on the ray grid: the pixels to measure (a region of interest), None: all.
        name: the view, for the log. keep_flow: keep the image-grid flow in the result.
    """
    u_image = FLOW.build(flow, distorted=distorted, reference=reference)
    h, w = grid_px
    u = resample(u_image, h, w).astype(np.float32) * np.float32(image_binning)  # px of the full sensor
    valid = np.isfinite(u).all(-1)
    if region is not None:
        valid &= np.asarray(region, dtype=bool)
    u[~valid] = np.nan
    peak = float(np.linalg.norm(u[valid], axis=-1).max()) if valid.any() else 0.0
    found = {"displacement_max_px": peak, "valid_fraction": float(valid.mean())}
    log.info("%s: displacement up to %.2f px%s", name or "view", peak,
             "" if valid.all() else f", {100 * (1 - found['valid_fraction']):.1f} % of the pixels unmeasured")
    return ViewMeasurement(u, valid, found, u_image if keep_flow else None)
