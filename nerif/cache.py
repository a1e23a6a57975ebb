"""The on-disk cache of computed arrays (synthetic observations, aperture renderings), keyed by what made them:
the settings, the content of the fields they were computed from, and the source code of the forward model.

Where: ``data.cache_dir`` (default ``$NERIF_CACHE``, else ``~/.cache/nerif``). Bounded: once it holds more than
``$NERIF_CACHE_MAX_MB`` (default 2048) the least recently used entries go. Delete the folder to clear it.
"""
from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Callable

import numpy as np

from nerif.io.export import write_npz

log = logging.getLogger(__name__)
DEFAULT_MAX_MB = 2048.0
# the source files (in the nerif package) whose code decides what a cached array holds; read, not imported
FORWARD_MODEL = ("physics.py", "geometry/box.py", "geometry/camera.py", "geometry/rays.py", "data/phantoms.py",
                 "data/scene.py", "renderers/voxel.py", "sensing/models.py", "sensing/realistic.py", "sensing/optics.py",
                 "sensing/imaging.py", "sensing/patterns.py", "sensing/flow.py", "sensing/displacement.py")


@functools.lru_cache(maxsize=1)
def forward_model_version() -> str:
    """A digest of the forward model's source files: any change to them makes new cache entries."""
    h = hashlib.sha256()
    for name in FORWARD_MODEL:
        h.update((Path(__file__).parent / name).read_bytes())
    return h.hexdigest()[:16]


def content_digest(array: np.ndarray) -> str:
    """A digest of an array's values, shape and dtype (what a field was computed from, wherever it came from)."""
    a = np.ascontiguousarray(array)
    return hashlib.sha256(str((a.shape, a.dtype.str)).encode() + a.tobytes()).hexdigest()[:32]


def cache_limit_bytes() -> float:
    value = os.environ.get("NERIF_CACHE_MAX_MB", DEFAULT_MAX_MB)
    try:
        return float(value) * 2**20
    except ValueError:
        raise ValueError(f"NERIF_CACHE_MAX_MB={value!r} must be a number of megabytes") from None


def evict(folder: Path, limit_bytes: float, keep: Path) -> None:
    """Remove the least recently used ``.npz`` entries of ``folder`` until it holds at most ``limit_bytes``
    (never ``keep``, the entry just written)."""
    entries = sorted(folder.glob("*.npz"), key=lambda p: p.stat().st_mtime)
    total = sum(p.stat().st_size for p in entries)
    for p in entries:
        if total <= limit_bytes:
            break
        if p != keep:
            total -= p.stat().st_size
            p.unlink(missing_ok=True)
            log.info("cache: removed %s (the cache holds at most NERIF_CACHE_MAX_MB)", p.name)


def cached_arrays(cache_dir, prefix: str, payload: dict, compute: Callable[[], dict]) -> dict:
    """``compute()`` (a dict of arrays), stored as ``<cache_dir>/<prefix>-<hash>.npz`` and read back from there
    next time; the hash is that of ``payload`` (which must name the content of every input, e.g. with
    :func:`content_digest`) and of :func:`forward_model_version`. ``cache_dir=None`` always computes."""
    limit = cache_limit_bytes()
    text = json.dumps({"payload": payload, "code": forward_model_version()}, sort_keys=True, default=str)
    key = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = Path(cache_dir).expanduser() / f"{prefix}-{key}.npz" if cache_dir else None
    if path is not None and path.is_file():
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
        os.utime(path)  # recently used
        return arrays
    arrays = compute()
    if path is not None:
        write_npz(path, **arrays)
        evict(path.parent, limit, path)
    return arrays
