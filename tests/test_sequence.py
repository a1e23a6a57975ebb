"""Time series (``data.frames``): every frame reconstructed in turn, warm-started from the one before; the series'
outputs (ParaView time series, per-frame table, figure, TensorBoard step per frame); resuming at the first
unfinished frame."""
import json
import xml.etree.ElementTree as ET

import pytest
import torch

from nerif.app import run
from nerif.configs import group
from nerif.data import DATASETS
from nerif.masks import MASKS
from tests.helpers import solver, tiny_config

FLICKER = ["phantom=flicker", "phantom.shape=[12,16,12]", "phantom.voxel_mm=4.0", "phantom.lift_mm=-24",
           "phantom.base_radius_mm=8", "phantom.flame_length_mm=40", "phantom.thickness_mm=3", "rig.n_cameras=6",
           "rig.binning=40", "data.cache_dir=null", "data.render_supersample=1", "data.frame_rate_hz=100"]


def series_config(*overrides):
    return tiny_config(*FLICKER, "data.frames=3", "train.iterations=120", "sequence.iterations=10", *overrides,
                       synthetic=False)


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    out = tmp_path_factory.mktemp("series")
    return out, run(series_config("figures=true"), out)  # the series' pictures are among its outputs


def test_a_series_writes_every_frame_and_the_series_outputs(series):
    out, m = series
    assert m["n_frames"] == m["frames_finished"] == 3 and m["iterations"] == 120 + 10 + 10
    assert [r["warm_start"] for r in m["frames"]] == [False, True, True]
    assert [r["time_s"] for r in m["frames"]] == pytest.approx([0.0, 0.01, 0.02])
    for k in range(3):
        frame = json.loads((out / f"frame_{k:04d}" / "metrics.json").read_text())
        assert frame["frame"] == k and frame["temperature_rmse_K"] > 0
        assert (out / f"frame_{k:04d}" / "reconstruction.vti").is_file()
        assert (out / f"frame_{k:04d}" / "rig.png").is_file() == (k == 0)  # the rig drawn once, with the cold frame
    assert m["temperature_rmse_K"] == pytest.approx(sum(r["temperature_rmse_K"] for r in m["frames"]) / 3)
    # the ParaView time series lists every frame's volume with its time
    sets = ET.parse(out / "sequence.pvd").getroot().find("Collection").findall("DataSet")
    assert [(float(d.get("timestep")), d.get("file")) for d in sets] == [
        (pytest.approx(0.01 * k), f"frame_{k:04d}/reconstruction.vti") for k in range(3)]
    assert all((out / d.get("file")).is_file() for d in sets)
    assert len((out / "frames.csv").read_text().splitlines()) == 4 and (out / "sequence.png").stat().st_size > 10_000
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(out / "tensorboard"), size_guidance={"images": 0, "scalars": 0}).Reload()
    assert [e.step for e in acc.Scalars("frame/temperature_rmse_K")] == [0, 1, 2]
    assert "frame/slices" in acc.Tags()["images"]


def test_resuming_a_series_continues_at_the_first_unfinished_frame(series, tmp_path):
    import shutil

    out = tmp_path / "series"
    shutil.copytree(series[0], out)
    (out / "frame_0002" / "metrics.json").unlink()  # frame 2 was interrupted (its checkpoint is kept)
    kept = {k: (out / f"frame_{k:04d}" / "metrics.json").stat().st_mtime_ns for k in (0, 1)}
    m = run(series_config("train.resume=auto"), out)
    assert {k: (out / f"frame_{k:04d}" / "metrics.json").stat().st_mtime_ns for k in (0, 1)} == kept
    assert (out / "frame_0002" / "metrics.json").is_file() and m["frames_finished"] == 3
    assert m["frames"][2]["iterations"] == 10  # from its own checkpoint, not again from frame 1


def test_cold_starts_and_bad_settings(tmp_path):
    m = run(series_config("sequence.warm_start=false", "data.frames=[1,2]", "train.iterations=30"), tmp_path / "cold")
    assert [(r["frame"], r["warm_start"], r["iterations"]) for r in m["frames"]] == [(1, False, 30), (2, False, 30)]
    for override, message in [("train.resume=/tmp/x.pt", "resumes from its own folder"),
                              ("solver=cgls", "solver=cgls cannot start a frame from the previous one"),
                              ("sequence.iterations=0", "at least 1 iteration")]:
        with pytest.raises(ValueError, match=message):
            run(series_config(override), tmp_path / "bad")
        assert not (tmp_path / "bad" / "frame_0000").exists()  # refused before any frame


def test_a_warm_frame_starts_from_the_previous_frame_s_field(series):
    """The second frame's solver holds the first frame's result (its averaged weights), and its first loss is far
    below a cold start's (the initial field is ambient: the loss is the data's own size)."""
    out = series[0]
    cfg = series_config()
    scene = DATASETS.build(group(cfg, "data"), frame=1)
    masks = MASKS.build(group(cfg, "mask"), scene=scene)
    warm, cold = solver(cfg, scene, masks), solver(cfg, scene, masks)
    previous = torch.load(out / "frame_0000" / "checkpoint.pt", weights_only=False)
    warm.start_from(out / "frame_0000" / "checkpoint.pt")
    assert int(previous["average"]["n_averaged"]) > 0  # the previous frame kept an average
    assert int(warm.optimisation.average.n_averaged) == 0  # a fresh one
    for k, v in warm.field.state_dict().items():
        assert torch.equal(v, previous["average"]["module." + k]), k
    assert warm.iteration == 0 and not warm.optimisation.optimizer.state  # a fresh optimiser
    assert warm.step()["loss"] < 0.3 * cold.step()["loss"]


def test_frame_ranges_as_jobs_of_a_multirun(tmp_path):
    """``-m data.frames=[0,1],[2]``: one job per range, each a series of its own (its first frame cold), every
    job a row of the sweep's summary."""
    import csv

    from tests.helpers import TINY, nerif_here

    base = [o for o in TINY if not o.startswith(("phantom", "rig.", "data."))] + FLICKER
    sweep = tmp_path / "sweep"
    r = nerif_here("-m", *base, "sequence.iterations=5", "data.frames=[0,1],[2]", f"hydra.sweep.dir={sweep}")
    assert r.returncode == 0, r.stderr[-2000:]
    rows = list(csv.DictReader((sweep / "summary.csv").open()))
    assert sorted(row["config"].split()[-1] for row in rows) == ["data.frames=[0,1]", "data.frames=[2]"]
    assert all(float(row["temperature_rmse_K"]) > 0 for row in rows)
    jobs = {json.loads((d / "metrics.json").read_text())["frames"][0]["frame"]: d for d in sweep.iterdir() if d.is_dir()}
    assert sorted(jobs) == [0, 2] and (jobs[2] / "frame_0002" / "metrics.json").is_file()
    assert [f["warm_start"] for f in json.loads((jobs[0] / "metrics.json").read_text())["frames"]] == [False, True]
