import os
from pathlib import Path

# Triton kernels (nerif.encoders.hash_kernel) run in Triton's interpreter on the CPU; the switch is read when a
# kernel is defined, so it is set before any test imports nerif.
os.environ.setdefault("TRITON_INTERPRET", "1")
# The runs of the suite write their data files without the pictures (config `figures`, 60 % of a tiny run's time);
# a test of a picture is marked `figures` and draws them.
os.environ["NERIF_FIGURES"] = "false"

import pytest

if os.environ.get("PYTEST_XDIST_WORKER_COUNT"):  # pytest -n K: K processes share the cores, a thread each by default
    import torch

    from tests.helpers import worker_threads

    torch.set_num_threads(worker_threads())
    # the share as a scheduler states it, for the runs left at threads=auto (and the Pythons they start): without it
    # a run here times its steps at counts the other processes' share (the default scene's test: 41 s, not 29)
    os.environ["OMP_NUM_THREADS"] = str(worker_threads())
# torch and nerif are imported where tests run, not here at the top: under -n K pytest's main process reads this
# file before it starts the workers, and it runs no test (importing them there delayed every worker by 3-4 s)


def pytest_report_header(config):
    """One line at the top of the run where the project's shared captures are not beside the clone."""
    from tests.paths import SHARED

    if not SHARED.is_dir():
        return (f"shared data: {SHARED} is not there (a fresh clone; set NERIF_SHARED to the folder holding data/): "
                "the tests of the shared captures are skipped")
    return None


@pytest.hookimpl(tryfirst=True)  # before xdist reads the groups off the items
def pytest_collection_modifyitems(config, items):
    """Under ``pytest -n K`` (with ``--dist loadgroup``, pyproject.toml) the tests that share a module or session
    fixture of this suite (a capture written, a series or an ensemble run) run in one process: it is built once,
    not once in each process that draws one of them."""
    for item in items:
        info = getattr(item, "_fixtureinfo", None)
        shared = sorted(f"{Path(defs[-1].baseid).stem}.{name}" for name in (info.names_closure if info else ())
                        if (defs := info.name2fixturedefs.get(name)) and defs[-1].scope in ("module", "session")
                        and defs[-1].baseid.startswith("tests"))
        if shared:
            item.add_marker(pytest.mark.xdist_group(shared[0]))


@pytest.fixture(autouse=True)
def _figures(request, monkeypatch):
    if request.node.get_closest_marker("figures"):
        monkeypatch.setenv("NERIF_FIGURES", "true")


@pytest.fixture(autouse=True)
def _seed():
    import torch

    torch.manual_seed(0)


@pytest.fixture(scope="session")
def written(tmp_path_factory):
    """(folder, scene, config): the 7-view tiny scene (:data:`tests.helpers.SMALL`) written as a capture folder,
    once a test process for every module that reads it (none may change it)."""
    from omegaconf import OmegaConf

    from nerif.data import DATASETS
    from nerif.write_capture import write_capture
    from tests.helpers import SMALL, tiny_config

    cfg = tiny_config(*SMALL)
    scene = DATASETS.build(OmegaConf.to_container(cfg.data, resolve=True), device="cpu")
    root = write_capture(scene, tmp_path_factory.mktemp("capture"))
    return root, scene, cfg


def pytest_collection_finish(session):
    """What collecting imported (torch, nerif, the test modules: most of a process's objects) moved out of the
    garbage collector's sight: its full collections during the runs and the five at the session's end (pytest's,
    for unraisable exceptions) walk only what the tests made. Put back at exit, so that the interpreter's last
    collection frees it (left frozen, Triton's bindings report their objects as leaked)."""
    import atexit
    import gc

    gc.collect()
    gc.freeze()
    atexit.register(gc.unfreeze)
