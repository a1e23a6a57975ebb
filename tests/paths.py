"""Where the clone and the project's shared data are: importable without torch or nerif (``tests/conftest.py`` reads
it in pytest's main process, which under ``-n K`` only hands tests to the workers)."""
import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]  # the clone
SHARED = Path(os.environ.get("NERIF_SHARED", ROOT.parent / "shared")) / "data"
