"""What a run will allocate, declared by its components before any work, against the memory there is.

Each registered component that allocates much declares it (:meth:`nerif.registry.Registry.allocations`): a dataset
its images and grids, a solver its field, tables and steps. Each estimate is an upper bound of the order of
magnitude of one large allocation (a factor of 2 either way): enough to refuse, in one sentence naming the key, a
setting that cannot fit, before it takes the machine's memory for minutes and ends in a MemoryError or the OOM
killer.
"""
from __future__ import annotations

import logging
import os
from pathlib import Path

import torch

log = logging.getLogger(__name__)
GIB = 2.0**30
FLOAT = 4  # bytes of a float32
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


def probe_grid(voxels: float, key: str) -> tuple[str, str, float]:
    """The allocation of a probe grid of ``voxels`` that ``key`` sets (:data:`PER_VOXEL` a voxel)."""
    return "the probe grid's volumes", key, voxels * PER_VOXEL


def check_memory(parts: list[tuple[str, str, float]], device: torch.device, share: float = 0.8) -> None:
    """One sentence, before any work, when the run's allocations ``parts`` (``(what, the key that sets it,
    bytes)`` each, as its components declare them) exceed ``share`` of the free memory of ``device``, naming the
    largest and the key that sets it."""
    need = sum(b for _, _, b in parts)
    free = available_bytes(device)
    if need <= share * free:
        return
    what, key, big = max(parts, key=lambda p: p[2])
    raise ValueError(f"this run would need about {need / GIB:.3g} GiB ({what} alone {big / GIB:.3g} GiB), more than "
                     f"the {free / GIB:.3g} GiB free on {device.type}: lower {key}")
