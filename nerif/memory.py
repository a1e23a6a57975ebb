"""What a run will allocate, estimated from its config before any work, against the memory there is.

Each estimate is an upper bound of the order of magnitude of one large allocation (a factor of 2 either way):
enough to refuse, in one sentence naming the key, a setting that cannot fit, before it takes the machine's
memory for minutes and ends in a MemoryError or the OOM killer.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from omegaconf import DictConfig

log = logging.getLogger(__name__)
GIB = 2.0**30
FLOAT = 4  # bytes of a float32
PER_PIXEL = 24  # bytes an image pixel of a capture's view takes over a run (both images, as read, measured, band-passed
               # and as B-spline coefficients): 6.0 GiB at 10 views of 25 megapixels, 1.2 GiB of it the run's own
PER_VOXEL = 96  # bytes a voxel of the probe grid takes over a run (the hull, the masks, the outputs): 95 measured
                # between 80^3 and 160^3 voxels on a capture


def available_bytes(device: torch.device) -> float:
    """Free memory of ``device`` [bytes]: the GPU's free memory, or the system's available memory."""
    if device.type == "cuda":
        return float(torch.cuda.mem_get_info(device)[0])
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    return float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def _phantom_voxels(phantom: DictConfig) -> Optional[float]:
    """Voxels of the phantom's grid: its ``shape``, or the header of a ``.npy`` file (other files: unknown)."""
    if "shape" in phantom and phantom.shape is not None:
        return float(np.prod([float(n) for n in phantom.shape]))
    path = phantom.get("path")
    if path and str(path).endswith(".npy") and Path(str(path)).expanduser().is_file():
        try:
            return float(np.prod(np.load(Path(str(path)).expanduser(), mmap_mode="r").shape))
        except (OSError, ValueError):
            return None
    return None


def estimates(cfg: DictConfig, probe: Optional[tuple[float, str]] = None,
              images: Optional[tuple[float, str]] = None, grid_factor: int = 1) -> list[tuple[str, str, float]]:
    """(what, the key that sets it, bytes) of a run's largest allocations. ``probe``: the voxels of the probe grid
    and the key that sets it, where the data read it from a file (a capture's rig file), else None; ``images``: the
    pixels of a capture's images and what sets them (:func:`nerif.data.capture.image_pixels`), else None;
    ``grid_factor``: the image term reads each reference on a grid this many times finer along each axis
    (``factor^2 - 1`` floats a pixel more than the coefficients counted in :data:`PER_PIXEL`)."""
    per_pixel = PER_PIXEL + FLOAT * (grid_factor**2 - 1)
    out = [("the images", images[1], images[0] * per_pixel)] if images is not None else []
    if cfg.data.name == "synthetic":
        voxels = _phantom_voxels(cfg.phantom)
        if voxels is not None:  # the phantom and its deflection field on the supersampled grid, float64
            ss = float(cfg.data.render_supersample)
            out.append(("the phantom on the rendering grid", "data.render_supersample", voxels * ss**3 * 8 * 4))
            probe = probe or (voxels, "phantom.shape")
    if probe is not None:
        out.append(("the probe grid's volumes", probe[1], probe[0] * PER_VOXEL))
    if cfg.solver.name != "nerif":
        return out
    field, train = cfg.field, cfg.train
    if cfg.sampler.name == "occupancy":  # density, its update and the bits
        out.append(("the occupancy grid", "field.occupancy_resolution", float(field.occupancy_resolution) ** 3 * 3 * FLOAT))
    hidden = [float(h) for h in field.hidden]
    features = 2.0 * float(field.hash_levels) if cfg.encoder.name == "hash" else 64.0
    widths = [features] + hidden + [1.0]
    params = sum(a * b + b for a, b in zip(widths[:-1], widths[1:]))
    out.append(("the MLP (weights, gradients, Adam's moments, the average)", "field.hidden", params * 5 * FLOAT))
    if cfg.encoder.name == "hash":
        table = float(field.hash_levels) * 2.0 ** float(field.log2_table_size) * 2
        out.append(("the hash tables", "field.log2_table_size", table * 5 * FLOAT))
    # a step: every sample evaluated at its 6 central-difference neighbours and itself, activations kept for
    # the backward pass
    samples = float(train.rays_per_batch) * float(cfg.sampler.samples_per_ray)
    out.append(("one training step's samples", "train.rays_per_batch or sampler.samples_per_ray",
                samples * 7 * (features + sum(hidden)) * 3 * FLOAT))
    return out


def check_memory(cfg: DictConfig, device: torch.device, share: float = 0.8,
                 probe: Optional[tuple[float, str]] = None, images: Optional[tuple[float, str]] = None,
                 grid_factor: int = 1) -> None:
    """One sentence, before any work, when the run's estimated allocations exceed ``share`` of the free memory of
    ``device``, naming the largest and the key that sets it (``probe``, ``images``, ``grid_factor``: as
    :func:`estimates` takes them)."""
    parts = estimates(cfg, probe, images, grid_factor)
    need = sum(b for _, _, b in parts)
    free = available_bytes(device)
    if need <= share * free:
        return
    what, key, big = max(parts, key=lambda p: p[2])
    raise ValueError(f"this run would need about {need / GIB:.3g} GiB ({what} alone {big / GIB:.3g} GiB), more than "
                     f"the {free / GIB:.3g} GiB free on {device.type}: lower {key}")
