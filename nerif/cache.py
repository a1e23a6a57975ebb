"""The on-disk cache of computed arrays (synthetic observations, aperture renderings), keyed by what made them.

Where: ``data.cache_dir`` (default ``$NERIF_CACHE``, else ``~/.cache/nerif``); delete the folder to clear it.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Callable

import numpy as np

from nerif.io.export import write_npz


def cached_arrays(cache_dir, prefix: str, payload: dict, compute: Callable[[], dict]) -> dict:
    """``compute()`` (a dict of arrays), stored as ``<cache_dir>/<prefix>-<hash of payload>.npz`` and read back
    from there next time; ``cache_dir=None`` always computes."""
    key = hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:16]
    path = Path(cache_dir).expanduser() / f"{prefix}-{key}.npz" if cache_dir else None
    if path is not None and path.is_file():
        with np.load(path) as f:
            return {k: f[k] for k in f.files}
    arrays = compute()
    if path is not None:
        write_npz(path, **arrays)
    return arrays
