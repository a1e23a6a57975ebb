"""Output folders: checked for writing before any work (by the app, and by Hydra before it makes its run folder)."""
from __future__ import annotations

import logging
import sys
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
