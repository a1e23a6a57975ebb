"""A tiny scene that trains in seconds on a CPU, building a solver from a config as the app does, three blobs whose
deflections are known in closed form, and the project's shared captures where they are."""
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from nerif.configs import compose, group
from nerif.geometry import ProbeBox
from nerif.physics import Ambient
from nerif.solvers import SOLVERS
from nerif.threads import usable_cores
from tests.paths import ROOT, SHARED


def worker_threads() -> int:
    """CPU threads of one test process: under ``pytest -n K`` its share of the cores it may use
    (:func:`nerif.threads.usable_cores`; ``tests/conftest.py`` sets torch's), else all of them."""
    return max(1, usable_cores() // int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")))


# a run of the suite starts with its process's share of the cores, told rather than measured (threads=auto samples
# the machine's load for 0.2 s a run, then times its steps at other counts: tests/test_threads.py)
TINY = [f"threads={worker_threads()}", "device=cpu", "phantom=gaussian_blob", "phantom.shape=[16,16,16]",
        "phantom.voxel_mm=3.0", "phantom.width_mm=7.0", "rig.n_cameras=6", "rig.binning=40",
        "sampler.samples_per_ray=16", "train.iterations=20", "train.rays_per_batch=64", "train.eval_every=10",
        "metrics.eval_rays_per_view=32", "train.checkpoint_every=10", "train.progress=false", "data.cache_dir=null",
        "data.render_supersample=1", "field.finest_resolution=32", "field.log2_table_size=12",
        "uncertainty=none"]  # the default (auto) trains members wherever a view is held out: tested on its own
# a capture of 7 views through the realistic chain (the `written` fixture of tests/conftest.py)
SMALL = ["rig.width_px=240", "rig.height_px=320", "rig.binning=8", "phantom.shape=[16,16,16]", "phantom.voxel_mm=2.0",
         "phantom.width_mm=6.0", "data.sensing=realistic", "data.sensor.aperture_rays=8", "rig.n_cameras=7"]


def tiny_config(*overrides, synthetic: bool = True):
    """The tiny scene's config; ``synthetic=False`` keeps only its solver settings (for another dataset)."""
    base = TINY if synthetic else [o for o in TINY if not o.startswith(("phantom", "rig.", "data."))]
    return compose(base + list(overrides))


def solver(cfg, scene, masks=None):
    """The configured solver, set up on ``scene`` (with ``masks``, default: none)."""
    from nerif.masks import Masks

    return SOLVERS.build(group(cfg, "solver")).setup(scene, masks if masks is not None else Masks())


def trained_on_half_the_box(iterations: int = 60):
    """(solver, scene): the tiny scene with the upper half of the box hidden from every view (its rays left out, no
    3-D mask), view 5 held out, trained for ``iterations``: where no ray reaches, the data say nothing."""
    from dataclasses import replace

    from nerif.data import DATASETS
    from nerif.data.scene import keep_rays
    from nerif.masks import MASKS

    cfg = tiny_config(f"train.iterations={iterations}", "mask=none")
    scene = DATASETS.build(group(cfg, "data"))
    rows = scene.pixel // scene.cameras[0].width
    dirs, eps, pixel, starts = keep_rays(scene.dirs, scene.eps, scene.pixel, scene.view_start,
                                         rows >= rows.double().median())
    scene = replace(scene, dirs=dirs, eps=eps, pixel=pixel, view_start=starts).split_views([5])
    s = solver(cfg, scene, MASKS.build(group(cfg, "mask"), scene=scene))
    s.fit(checkpoint_every=10**9, progress=False)
    return s, scene


def shared_data(name: str) -> Path:
    """The folder ``name`` of the project's shared data (``../shared/data`` beside the clone, or
    ``$NERIF_SHARED/data``); where it is not there (a fresh clone), the test is skipped with one line saying so."""
    path = SHARED / name
    if not path.is_dir():
        pytest.skip(f"the project's shared data are not beside this clone ({SHARED}; set NERIF_SHARED to the folder "
                    "holding data/): tests of the shared captures skipped")
    return path


def refusal(*args, out_dir) -> str:
    """The one sentence ``python -m nerif ARGS`` refuses bad ``args`` with ('' where the run went ahead into
    ``out_dir``), found by the command's own two steps (:func:`nerif.__main__.refused`, then
    :func:`nerif.__main__.execute`) on the config composed once a process for its group choices
    (:func:`nerif.configs.compose`), not by Hydra's two composes of every yaml a run (0.7 s). That the command
    says it without a traceback and exits with status 2: :func:`nerif_here` and a new Python."""
    from nerif.__main__ import execute, refused, sentence

    said = refused(list(args))
    if said:
        return said
    try:
        execute(compose(list(args)), list(args), out_dir)
    except (ValueError, FileNotFoundError) as e:  # what the command says as bad input
        return sentence(e)
    return ""


def nerif_here(*args, cwd=ROOT) -> subprocess.CompletedProcess:
    """``python -m nerif ARGS`` in this process (no 6-8 s of imports): ``sys.argv`` set, what it prints captured,
    the status its ``SystemExit`` carries (0 where it returns). Hydra's state and the logging handlers it installs
    (which write to the captured streams) are put back afterwards."""
    import contextlib
    import io
    import logging

    from hydra.core.global_hydra import GlobalHydra

    from nerif.__main__ import cli

    out, err, code = io.StringIO(), io.StringIO(), 0
    argv, here, handlers = sys.argv, os.getcwd(), list(logging.getLogger().handlers)
    try:
        sys.argv = ["nerif", *args]
        os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                cli()
            except SystemExit as e:
                code = e.code if isinstance(e.code, int) else int(e.code is not None)
    finally:
        sys.argv = argv
        os.chdir(here)
        GlobalHydra.instance().clear()
        root = logging.getLogger()
        for h in root.handlers:
            if h not in handlers:
                h.close()
        root.handlers[:] = handlers
    return subprocess.CompletedProcess(["nerif", *args], code, out.getvalue(), err.getvalue())


# Three Gaussian blobs of sigma in a small probe box, whose deflections along any line are known in closed form: a
# field that is not axisymmetric, for tests of geometry (poses) and of scores against known noise (evaluation).
BLOBS = [((8.0, 4.0, -5.0), 4.0, -1.0), ((-6.0, -6.0, 7.0), 3.0, -0.6), ((2.0, 9.0, 9.0), 3.5, -0.4)]  # c, w, A
BOX, AMBIENT = ProbeBox((20, 24, 20), 2.0), Ambient(296.15, 1.00027, 2000.0)


def analytic(o: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """(R, 3) deflections of sigma of :data:`BLOBS` along whole lines (o, d), in closed form: a blob
    ``A exp(-|x - c|^2 / 2 w^2)`` deflects a line passing at ``b`` (from c to the line's nearest point) by
    ``-A sqrt(2 pi) b / w exp(-|b|^2 / 2 w^2)``; nothing along the line."""
    o, d = o.double(), d.double()
    out = torch.zeros_like(o)
    for c, w, A in BLOBS:
        c = torch.tensor(c, dtype=torch.float64)
        b = o + ((c - o) * d).sum(-1, keepdim=True) * d - c
        out += -A * math.sqrt(2 * math.pi) / w * b * torch.exp(-(b * b).sum(-1, keepdim=True) / (2 * w * w))
    return out
