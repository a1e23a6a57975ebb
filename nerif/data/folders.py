"""Checks shared by the readers of real data (:mod:`nerif.data.capture`, :mod:`nerif.data.transforms`): the
dataset folder, the binning of the ray grid, a region of interest on the sensor, displacement estimates that are
not finite, and the true temperature of a rendered dataset."""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import numpy as np

from nerif.data.phantoms import read_volume
from nerif.geometry import Camera, ProbeBox, pixels_per_voxel, ray_binning
from nerif.physics import check_temperature
from nerif.sensing.imaging import resample

log = logging.getLogger(__name__)


COARSE = 2.5  # rays wider than this many voxels of the probe grid leave its detail unmeasured (warned)


def resolve_binning(setting, cameras: list[Camera], box: Optional[ProbeBox], sensor: str) -> int:
    """``data.binning`` for these full-sensor ``cameras``: ``auto`` (about one ray per voxel of ``box`` across,
    :func:`nerif.geometry.ray_binning`, logged), or a whole number that divides every camera's sensor (``sensor``
    names it); one sentence otherwise."""
    if setting == "auto":
        b, per_voxel = ray_binning(cameras, box), pixels_per_voxel(cameras, box)
        log.info("data.binning=auto: %d x %d pixels a ray (%.1f pixels span a voxel of %g mm at the probe centre)",
                 b, b, per_voxel, box.voxel_mm)
        if per_voxel > 0 and not 0.5 <= b / per_voxel <= 2.0:
            log.warning("data.binning=auto: %d x %d pixels a ray is the nearest block that divides %s, but a voxel "
                        "spans %.1f pixels; set data.binning (or crop the images to a size it divides)",
                        b, b, sensor, per_voxel)
        return b
    if isinstance(setting, float) and setting.is_integer():
        setting = int(setting)  # 4.0 is 4
    if isinstance(setting, bool) or not isinstance(setting, int) or setting < 1:
        raise ValueError(f"data.binning={setting!r}: auto or a whole number of pixels (at least 1)")
    if any(c.width % setting or c.height % setting for c in cameras):
        raise ValueError(f"data.binning={setting} must divide {sensor}")
    per_voxel = pixels_per_voxel(cameras, box) if box is not None else 0.0
    if per_voxel > 0 and setting > COARSE * per_voxel:
        cam = cameras[0]
        log.warning("data.binning=%d: a ray spans %.1f voxels of the probe grid across (%d x %d rays a view), so the "
                    "field's detail finer than that is not measured; lower data.binning (auto: %d)", setting,
                    setting / per_voxel, cam.width // setting, cam.height // setting, ray_binning(cameras, box))
    return setting


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
        log.info("%s: %d of %d displacement estimates are left out (not measured: see the measurement lines)", what,
                 bad, ok.size)
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
