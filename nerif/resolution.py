"""The resolution of a reconstruction, and what it does to the peak a combustion researcher reads first.

A run cannot show structure finer than its finest cells: the field's finest cell (a hash's finest level, a voxel of a
voxel solver) and the spacing of its rays at the probe (the displacements between two rays are interpolated from
theirs). Each acts as a linear interpolation over its cell, a tent whose standard deviation is the cell over sqrt(6);
together they blur the true field by about a Gaussian of

    s = sqrt(cell_field^2 + cell_rays^2) / sqrt(6)                     [mm]  (:func:`effective_resolution_mm`)

(0.79 mm on the shared 1 mm captures: a 1.56 mm hash cell, rays 1.14 mm apart). A hot core not much wider than ``s``
reads cold: blurring a flame's truth by 0.8 mm takes its 1861 K peak to 1570 K, and its temperature falls faster
than sigma near the peak (``dT / T = -d(T0 / T) / (T0 / T)``: at 1860 K a 1 % error of sigma is 5 % of T).

:func:`resolved_peak` reads the peak back through that blur: a reconstruction ``R = G_s * truth`` has
``truth ~ R - (G_s * R - R)`` to first order (one van Cittert step, exact for a core much wider than ``s``; it
corrects too little for a narrower one, never too much), applied at the field's hottest voxel alone (the whole field
sharpened loses in L2: it amplifies every voxel's noise). Where that correction exceeds :data:`UNRESOLVED` of the
peak's sigma, the core is about as fine as ``s`` (or the peak a spike of crossing streaks) and the first order no
longer holds: the field's own peak is reported, and that it cannot be read more closely is said in one sentence.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TENT = 1.0 / np.sqrt(6.0)  # the standard deviation of a linear interpolation's tent, in cells
UNRESOLVED = 0.10  # a first-order correction above this share of the peak's sigma: the core is as fine as the run
FLAME = 0.05  # a voxel of sigma above -FLAME is no flame: a peak there has no core to resolve, and
# nerif.field.prior_saturation counts the flame's voxels below it


def effective_resolution_mm(cell_mm: float, ray_spacing_mm: float) -> float:
    """The standard deviation [mm] of the Gaussian blur a run puts on the true field: the tents of the field's
    finest cell ``cell_mm`` and of the rays' spacing at the probe ``ray_spacing_mm`` (both [mm];
    :func:`nerif.geometry.ray_spacing_mm`) combined."""
    return float(np.hypot(cell_mm, ray_spacing_mm) * TENT)


@dataclass(frozen=True)
class ResolvedPeak:
    """The hottest voxel of a reconstruction read through its resolution (all sigma: hot gas is negative).

    Attributes:
        index: (i, j, k) of the field's hottest voxel.
        sigma_field: the field's sigma there.
        deficit: what the blur took off it (>= 0): ``G_s * sigma - sigma`` there.
        sigma: the peak corrected for it, ``sigma_field - deficit``, no hotter than the prior allows; where the
            deficit exceeds :data:`UNRESOLVED` of ``|sigma_field|`` (beyond the first order: a core as fine as the
            run, or a spike of crossing streaks, which the correction would only sharpen) the field's own.
        resolved: False there.
        resolution_mm: ``s`` [mm].
        remainder: the series' next term there, ``|(G_s - 1)^2 sigma|`` (>= 0): what the first order leaves of a
            resolved core is 1.05-1.25 times it (Gaussian cores 3-8 times wider than ``s``), always hotter.
    """

    index: tuple
    sigma_field: float
    deficit: float
    sigma: float
    resolved: bool
    resolution_mm: float
    remainder: float


def blur_deficit(sigma: np.ndarray, blur_vox: float) -> np.ndarray:
    """``G * sigma - sigma`` (nx, ny, nz) at every voxel, G a Gaussian of ``blur_vox`` voxels (standard deviation):
    what a blur of that width takes off each voxel (positive at a hot local peak, whose sigma is lowest)."""
    from scipy.ndimage import gaussian_filter

    sigma = np.asarray(sigma, dtype=np.float64)
    return gaussian_filter(sigma, blur_vox, mode="nearest") - sigma if blur_vox > 0 else np.zeros_like(sigma)


def resolved_peak(sigma: np.ndarray, resolution_mm: float, voxel_mm: float, hottest_sigma: float,
                  correct: bool = True) -> ResolvedPeak:
    """The hottest voxel of ``sigma`` (nx, ny, nz) corrected to first order for a Gaussian blur of
    ``resolution_mm`` (voxels of ``voxel_mm``), no hotter than ``hottest_sigma`` (the prior's bound). ``correct``
    False: the deficit is weighed (``resolved``) but the field's own peak kept, for exact deflections, which leave the
    field sharper than ``s`` (a 2 mm core through exact deflections is blurred by 0.34 mm; corrected at ``s`` its
    1731 K would read 2003 K for 1800: ``benchmarks/resolution.py``). A field without a flame (no voxel below
    :data:`FLAME`) has no core to resolve."""
    sigma = np.asarray(sigma, dtype=np.float64)
    at = np.unravel_index(np.argmin(sigma), sigma.shape)
    first = blur_deficit(sigma, resolution_mm / voxel_mm)
    deficit = max(float(first[at]), 0.0)
    remainder = abs(float(blur_deficit(first, resolution_mm / voxel_mm)[at]))
    field = float(sigma[at])
    resolved = deficit <= UNRESOLVED * abs(field) or field > -FLAME
    corrected = max(field - deficit, float(hottest_sigma)) if resolved and correct and field <= -FLAME else field
    return ResolvedPeak(index=tuple(int(i) for i in at), sigma_field=field, deficit=deficit, sigma=corrected,
                        resolved=resolved, resolution_mm=float(resolution_mm), remainder=remainder)
