"""The on-disk cache of computed arrays (synthetic observations, aperture renderings), keyed by what made them:
the settings, the content of the fields they were computed from, and the source code of the forward model.

Where: ``data.cache_dir`` (default ``$NERIF_CACHE``, else ``~/.cache/nerif``). Bounded: once it holds more than
``$NERIF_CACHE_MAX_MB`` (default 2048) the least recently used entries go. Delete the folder to clear it.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import json
import logging
import os
import time
import zipfile
from pathlib import Path
from typing import Callable, Optional, Sequence

import numpy as np

from nerif.export import write_npz

log = logging.getLogger(__name__)
DEFAULT_MAX_MB = 2048.0
# the modules whose code decides what a cached array holds: the forward model is their import closure
FORWARD_MODEL_ROOTS = ("nerif.data.synthetic", "nerif.sensing.realistic")
_TOP = Path(__file__).resolve().parent  # the nerif package


def module_file(name: str, top: Path = _TOP) -> Optional[Path]:
    """The source file of module ``name`` (``nerif.a.b``) in the package folder ``top``: ``a/b.py`` or
    ``a/b/__init__.py``; None for a name that is no module there (an attribute imported from a package)."""
    parts = name.split(".")[1:]
    for path in (top.joinpath(*parts).with_suffix(".py") if parts else None, top.joinpath(*parts, "__init__.py")):
        if path is not None and path.is_file():
            return path
    return None


def _read(path: Path) -> dict:
    """What a source file says of the modules it runs, read, not run: ``imports`` (the ``nerif...`` modules it
    imports, at its top or inside a function; ``from nerif.a import b`` names ``nerif.a`` and ``nerif.a.b``, b may
    be a module), ``defines`` (name -> package of each :class:`nerif.registry.Registry` it defines), ``looks_up``
    (the names whose attributes other than ``register`` it uses: a registry it builds from) and ``registers``
    (the names whose ``register`` it calls)."""
    out = {"imports": set(), "defines": {}, "looks_up": set(), "registers": set()}
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "nerif":
            out["imports"].add(node.module)
            out["imports"].update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            out["imports"].update(a.name for a in node.names if a.name.split(".")[0] == "nerif")
        elif isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) \
                and getattr(node.value.func, "id", None) == "Registry":
            for kw in node.value.keywords:
                if kw.arg == "package" and isinstance(kw.value, ast.Constant):
                    out["defines"].update({t.id: kw.value.value for t in node.targets if isinstance(t, ast.Name)})
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            out["registers" if node.attr == "register" else "looks_up"].add(node.value.id)
        elif isinstance(node, ast.Compare) and isinstance(node.comparators[0], ast.Name):  # ``name in REGISTRY``
            out["looks_up"].add(node.comparators[0].id)
    return out


def _package_files(package: str, top: Path) -> list[Path]:
    """Every source file of ``package`` and of its subpackages (a registry imports them all)."""
    init = module_file(package, top)
    return sorted(init.parent.rglob("*.py")) if init is not None and init.name == "__init__.py" else []


def _module_name(path: Path, top: Path) -> str:
    parts = path.relative_to(top).with_suffix("").parts
    return ".".join(("nerif",) + (parts[:-1] if parts[-1] == "__init__" else parts))


def import_closure(roots: Sequence[str], top: Path = _TOP) -> list[Path]:
    """The source files that decide what the modules ``roots`` compute, as sorted paths in ``top``, the package
    folder: what they import (:func:`_read`, recursively, with the ``__init__.py`` of every package on the way)
    and, for each registry they look a name up in, the modules of its package (subpackages too) that register into
    it: a registry imports its whole package, but only what registers into it decides what it builds (an edit to
    the capture reader leaves the phantoms, built from the same package, as they are)."""
    seen: set[Path] = set()
    defines: dict[str, str] = {}
    looks_up: set[str] = set()
    expanded: set[str] = set()
    todo = list(roots)
    while todo:
        while todo:
            parts = todo.pop().split(".")
            for k in range(1, len(parts) + 1):  # the packages on the way, then the module itself
                path = module_file(".".join(parts[:k]), top)
                if path is not None and path not in seen:
                    seen.add(path)
                    said = _read(path)
                    todo.extend(said["imports"])
                    defines.update(said["defines"])
                    looks_up |= said["looks_up"]
        for name in sorted((looks_up & defines.keys()) - expanded):
            expanded.add(name)
            todo.extend(_module_name(p, top) for p in _package_files(defines[name], top)
                        if p not in seen and name in _read(p)["registers"])
    return sorted(seen)


def forward_model_version(top: Optional[Path] = None) -> str:
    """A digest of the forward model's source files (:func:`import_closure` of :data:`FORWARD_MODEL_ROOTS` in
    the package folder ``top``, default this nerif's): any change to one of them makes new cache entries."""
    return _digest(Path(top or _TOP))


@functools.lru_cache(maxsize=4)
def _digest(top: Path) -> str:
    h = hashlib.sha256()
    for path in import_closure(FORWARD_MODEL_ROOTS, top):
        h.update(str(path.relative_to(top)).encode() + b"\0" + path.read_bytes())
    return h.hexdigest()[:16]


def source_digest(*modules) -> str:
    """A digest of ``modules``' source files: what a value cached outside the forward model (a picture, an image
    term's scale) depends on besides its inputs, so that a change to their code makes new entries."""
    h = hashlib.sha256()
    for module in modules:
        h.update(Path(module.__file__).read_bytes())
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
    (never ``keep``, the entry just written). A write killed before its rename leaves a ``.*.tmp`` file: those
    older than an hour (no write takes that long) are removed first."""
    now = time.time()
    for p in folder.glob(".*.tmp"):
        try:
            if now - p.stat().st_mtime > 3600:
                p.unlink()
                log.info("cache: removed %s, left by an interrupted write", p.name)
        except OSError:  # removed meanwhile by another process
            pass
    entries = sorted(folder.glob("*.npz"), key=lambda p: p.stat().st_mtime)
    total = sum(p.stat().st_size for p in entries)
    for p in entries:
        if total <= limit_bytes:
            break
        if p != keep:
            total -= p.stat().st_size
            p.unlink(missing_ok=True)
            log.info("cache: removed %s (the cache holds at most NERIF_CACHE_MAX_MB)", p.name)


def usable(folder: Path) -> None:
    """The cache folder exists (made if need be) and takes files; one sentence otherwise, before any work."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"the cache folder {folder} (data.cache_dir, default $NERIF_CACHE) cannot be written "
                         f"({e.strerror or e}): point it at a writable folder, or set data.cache_dir=null") from None


def cached_arrays(cache_dir, prefix: str, payload: dict, compute: Callable[[], dict]) -> dict:
    """``compute()`` (a dict of arrays), stored as ``<cache_dir>/<prefix>-<hash>.npz`` and read back from there
    next time; the hash is that of ``payload`` (which must name the content of every input, e.g. with
    :func:`content_digest`) and of :func:`forward_model_version`. ``cache_dir=None`` always computes."""
    limit = cache_limit_bytes()
    text = json.dumps({"payload": payload, "code": forward_model_version()}, sort_keys=True, default=str)
    key = hashlib.sha256(text.encode()).hexdigest()[:16]
    path = Path(cache_dir).expanduser() / f"{prefix}-{key}.npz" if cache_dir else None
    if path is not None:
        usable(path.parent)
    if path is not None and path.is_file():
        try:
            with np.load(path, allow_pickle=False) as f:
                arrays = {k: f[k] for k in f.files}
            os.utime(path)  # recently used
            return arrays
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:  # damaged: computed again, replaced
            log.warning("cache: %s is damaged (%s): computing it again", path, type(e).__name__)
            path.unlink(missing_ok=True)
    arrays = compute()
    if path is not None:
        write_npz(path, **arrays)
        evict(path.parent, limit, path)
    return arrays
