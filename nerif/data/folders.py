"""Checks shared by the readers of real data (:mod:`nerif.data.capture`, :mod:`nerif.data.transforms`): the
dataset folder, a region of interest on the sensor, displacement estimates that are not finite, and the true
temperature of a rendered dataset."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from nerif.data.phantoms import read_volume
from nerif.geometry import ProbeBox
from nerif.physics import check_temperature
from nerif.sensing.imaging import resample

log = logging.getLogger(__name__)


def region_of_interest(x: int, y: int, w: int, h: int, width: int, height: int, what: str) -> np.ndarray:
    """(height, width) bool, True on the pixels [x, x + w) x [y, y + h) (0-based); a clear error naming ``what``
    when the rectangle is not inside the image."""
    if not (0 <= x and 0 <= y and w > 0 and h > 0 and x + w <= width and y + h <= height):
        raise ValueError(f"{what} is not inside the {width} x {height} px image")
    roi = np.zeros((height, width), bool)
    roi[y:y + h, x:x + w] = True
    return roi


def blocks_inside(region: np.ndarray, height: int, width: int) -> np.ndarray:
    """A (H, W) bool region -> (height, width) bool on a coarser grid of the same sensor: blocks wholly inside."""
    return resample(region.astype(np.float32), height, width) > 1 - 1e-6


def dataset_folder(root) -> Path:
    """``data.root`` as an existing folder, or a clear error."""
    if root in (None, "", "???"):
        raise ValueError("data.root is not set: give the dataset folder, e.g. data.root=/path/to/folder")
    path = Path(str(root)).expanduser()
    if not path.is_dir():
        raise FileNotFoundError(f"data.root={root} is not a folder")
    return path


def finite_or_masked(u: np.ndarray, what: str) -> np.ndarray:
    """(..., 2) displacements -> (...) bool, False where a component is NaN or infinite (with a warning)."""
    ok = np.isfinite(u).all(-1)
    bad = int(ok.size - ok.sum())
    if bad:
        log.warning("%s: %d of %d displacement estimates are not finite; those rays are left out", what, bad, ok.size)
    return ok




def read_truth(path, box: ProbeBox) -> np.ndarray:
    """``data.truth``: the true temperature [K] on the probe grid (nx, ny, nz), from a volume file (``.npy``, or
    the array ``T`` of a file holding several); one sentence when it is not one or does not fit the grid."""
    try:
        T = read_volume(path, "data.truth")
    except ValueError as e:
        if "holds" not in str(e):
            raise
        T = read_volume(path, "data.truth", key="T")
    if T.shape != tuple(box.shape):
        raise ValueError(f"data.truth {path} has shape {T.shape}, the probe grid is {tuple(box.shape)}")
    check_temperature(T, f"data.truth {path}")
    return T
