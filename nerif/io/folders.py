"""Output folders: checked for writing before any work (by the app, and by Hydra before it makes its run folder)."""
from __future__ import annotations

import logging
import os
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

log = logging.getLogger("nerif")


def check_writable(folder: Path, key: str = "hydra.run.dir") -> None:
    """Make ``folder`` (and its parents) and write a probe file in it; one sentence naming ``key`` otherwise."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        probe = folder / ".nerif-write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        raise ValueError(f"the output folder {folder} cannot be written ({e.strerror or e}); choose another with "
                         f"{key}=...") from None


RUN_OUTPUTS = ("metrics.json", "checkpoint.pt", "reconstruction.npz", "sequence.pvd", "frame_0000")
LOCK_FILE = ".nerif.lock"


@contextmanager
def run_folder(folder: Path, continuing: bool):
    """Hold ``folder`` for one run: refused in one sentence when another run is writing there (an advisory lock,
    released by the system if the process dies), or when it holds an earlier run's results and this run does not
    continue it (``continuing``: ``train.resume`` set, or a requeued job), which would overwrite them."""
    import fcntl

    folder = Path(folder)
    if not continuing:
        found = [name for name in RUN_OUTPUTS if (folder / name).exists()]
        if found:
            raise ValueError(f"{folder} holds an earlier run ({', '.join(found)}): continue it with train.resume=auto, "
                             "or write this run elsewhere with hydra.run.dir=...")
    handle = open(folder / LOCK_FILE, "a+")
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            who = handle.read().strip() or "another process"
            raise ValueError(f"another nerif run ({who}) is writing to {folder}: wait for it to end, or write this "
                             "run elsewhere with hydra.run.dir=...") from None
        handle.seek(0)
        handle.truncate()
        handle.write(f"pid {os.getpid()}")
        handle.flush()
        yield folder
    finally:
        handle.close()


class OutputFolderCheck(Callback):
    """Hydra callback: the run (or sweep) folder must be writable before Hydra makes it; else one line, exit 2."""

    @staticmethod
    def _check(folder: str, key: str) -> None:
        try:
            check_writable(Path(folder), key)
        except ValueError as e:
            print(f"nerif: error: {e}", file=sys.stderr, flush=True)
            sys.exit(2)

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check(config.hydra.run.dir, "hydra.run.dir")

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        self._check(config.hydra.sweep.dir, "hydra.sweep.dir")
