"""A run from a resolved config: the device and threads, then one reconstruction (:mod:`nerif.reconstruct`) or
every frame of a time series (:mod:`nerif.sequence`)."""
from __future__ import annotations

import ctypes
import ctypes.util
import logging
import platform
import time
from pathlib import Path

import torch
from omegaconf import DictConfig

from nerif.configs import check_settings, group
from nerif.data import DATASETS
from nerif.io.folders import check_writable, run_folder
from nerif.memory import check_memory
from nerif.reconstruct import WarningRecords, reconstruct, resuming
from nerif.sequence import frames_of, run_sequence
from nerif.solvers.base import SOLVERS
from nerif.threads import ThreadTuner, resolve_threads, thread_budget

DEVICES = "auto, cpu, cuda or cuda:N"
log = logging.getLogger(__name__)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters (malloc.h)


def resolve_device(name: str) -> torch.device:
    """``auto`` (cuda when available, else cpu), ``cpu``, ``cuda`` or ``cuda:N``; one sentence otherwise."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        dev = torch.device(str(name))
    except RuntimeError:
        dev = None
    if dev is None or dev.type not in ("cpu", "cuda"):
        raise ValueError(f"device={name} is not one nerif runs on; use {DEVICES}")
    if dev.type == "cuda" and dev.index is not None and dev.index >= torch.cuda.device_count():
        raise ValueError(f"device={name}: this machine has {torch.cuda.device_count()} CUDA GPU(s)")
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={name} was asked for but no CUDA GPU is available; use device=cpu or auto")
    return dev


def retain_freed_memory() -> bool:
    """Let the process keep the memory its tensors free (glibc: blocks up to 32 MiB from the heap, which is never
    trimmed), instead of handing it back to the system and faulting it in again on the next step. A training step
    allocates and frees tens of tensors of megabytes each on the CPU; with glibc's defaults that churn cost about a
    third of a step on the default scene (benchmarks/RESULTS.md). The memory held stays at the run's peak.
    Returns whether it applied (glibc only; elsewhere nothing changes)."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        ok = libc.mallopt(_M_MMAP_THRESHOLD, 32 << 20) == 1 and libc.mallopt(_M_TRIM_THRESHOLD, 1 << 30) == 1
    except (OSError, AttributeError):
        ok = False
    if not ok:
        log.debug("could not set glibc's malloc thresholds: freed tensor memory goes back to the system")
    return ok


def unexpected(e: BaseException, debug: str) -> str:
    """One sentence for an exception nerif did not turn into one where it arose (OpenCV's, torch's, a TypeError
    from a value of the wrong kind): its type and first line, and the flag (``debug``) that shows where it arose."""
    said = getattr(e, "err", None) or str(e)  # cv2.error: its short message
    first = next((ln.strip() for ln in str(said).splitlines() if ln.strip()), "")
    return f"nerif stopped on {type(e).__name__}: {first or 'no message'} (add {debug} to see where it arose)"


def allocations(cfg: DictConfig) -> list[tuple[str, str, float]]:
    """What the run configured by ``cfg`` will allocate, as its dataset and its solver declare it (:mod:`nerif.memory`):
    ``(what, the key that sets it, bytes)`` each."""
    return DATASETS.allocations(cfg, "data") + SOLVERS.allocations(cfg, "solver")


def check_outside_capture(cfg: DictConfig, out_dir: Path) -> None:
    """One sentence where the run would write into the folder its data are read from (``data.root``, of any dataset
    that reads one): the run's images (``slices.png``, ...) would mix with the data's, and a capture reads every image
    of its folder as a view."""
    root = cfg.data.get("root")
    if root in (None, "???"):
        return
    root, out = Path(str(root)).expanduser().resolve(), Path(out_dir).resolve()
    if out == root or root in out.parents:
        raise ValueError(f"hydra.run.dir={out_dir} is inside the capture folder data.root={cfg.data.root}: its images "
                         "would be read as views by the next run; write the run elsewhere")


def run(cfg: DictConfig, out_dir: Path, parallel_jobs: int = 1) -> dict:
    """Reconstruct the configured scene into ``out_dir``, or every frame of a time series (``data.frames``;
    :func:`nerif.sequence.run_sequence`); returns the final metrics. ``parallel_jobs``: jobs of a multirun
    running at once on this machine (``threads=auto`` shares the cores among them; a job alone keeps the fastest
    count under the machine's load, :class:`nerif.threads.ThreadTuner`)."""
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    check_settings(cfg)
    device = resolve_device(cfg.device)
    check_memory(allocations(cfg), device)
    with WarningRecords() as early:  # what the log warns of before the data is read goes to metrics.json too
        threads = resolve_threads(cfg.threads, parallel_jobs)
    torch.set_num_threads(threads)
    tuner = None
    if cfg.threads == "auto" and parallel_jobs <= 1 and device.type == "cpu":
        tuner = ThreadTuner(thread_budget(), torch.set_num_threads)
        tuner.start(threads)
    retain_freed_memory()
    check_outside_capture(cfg, out_dir)
    check_writable(out_dir)
    continuing = cfg.train.resume is not None or resuming(cfg.train.resume)
    with run_folder(out_dir, continuing):
        frames = frames_of(group(cfg, "data"))  # a time series is checked whole here, before any work
        if frames is not None:
            return run_sequence(cfg, out_dir, device, frames, threads=tuner, warned=tuple(early.messages))
        return reconstruct(cfg, out_dir, device, t_start=t_start, threads=tuner, about={"warnings": early.messages})
