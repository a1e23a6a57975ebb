"""The mask registry and what every mask builder returns.

A mask builder takes the scene and returns :class:`Masks`: which rays training draws from, and the gate
(N, 3) [mm] -> (N,) in [0, 1] that multiplies the field (None: no gate). Every module of :mod:`nerif.masks`
registers its builders in :data:`MASKS`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import torch

from nerif.registry import Registry

MASKS = Registry("mask", package="nerif.masks")


@dataclass
class Masks:
    """Attributes:
        images: per view, (height, width) bool 2-D mask, or None (train on every ray).
        inside: per view, scene indices of the rays inside the 2-D mask (None with no 2-D mask).
        gate: the 3-D gate, or None.
        volume: (nx, ny, nz) bool 3-D mask on the probe grid, or None.
    """

    images: Optional[list[np.ndarray]] = None
    inside: Optional[list[torch.Tensor]] = None
    gate: Optional[object] = None
    volume: Optional[np.ndarray] = None


@MASKS.register("none")
def no_mask(scene) -> Masks:
    """Train on every ray; no gate."""
    return Masks()
