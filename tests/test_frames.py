"""Frames of a time series: which frames ``data.frames`` picks, and the synthetic frames of a changing phantom."""
import numpy as np
import pytest

from nerif.data import DATASETS
from nerif.data.frames import Frame, pick_frames
from nerif.sequence import frames_of
from tests.helpers import tiny_config
from nerif.configs import group


@pytest.mark.parametrize("setting, available, picked", [
    (None, 4, [0, 1, 2, 3]), (3, None, [0, 1, 2]), (3, 5, [0, 1, 2]), ([1, 4], 5, [1, 4]), ([0], None, [0])])
def test_pick_frames(setting, available, picked):
    assert pick_frames(setting, available) == picked


@pytest.mark.parametrize("setting, available, message", [
    (0, None, "at least 1 frame"), ([2, 1], None, "increasing order"), ([1, 1], None, "increasing order"),
    ([-1, 0], None, "increasing order"), (6, 5, "hold 5 frame"), ([0, 5], 5, "numbered 0 to 4"),
    ("all", None, "a number of frames"), ([0.5], None, "a number of frames"), (None, None, "how many frames")])
def test_bad_frame_picks_are_one_sentence(setting, available, message):
    with pytest.raises(ValueError, match=message):
        pick_frames(setting, available)


FLICKER = ["phantom=flicker", "phantom.shape=[12,16,12]", "phantom.voxel_mm=4.0", "rig.n_cameras=4", "rig.binning=40",
           "data.cache_dir=null", "data.render_supersample=1"]


def test_synthetic_frames_are_the_phantom_at_successive_times():
    """Frame k is the phantom at time_s + k / frame_rate_hz: at 24 frames/s, frame 1 is the 12 Hz flame half a
    period on (another state, the one a scene starting then shows), frame 2 a whole period on (the same state)."""
    data = group(tiny_config(*FLICKER, "data.frames=3", "data.frame_rate_hz=24", synthetic=False), "data")
    frames = frames_of(data)
    assert frames == [Frame(0, 0.0), Frame(1, 1 / 24), Frame(2, 2 / 24)]
    T = [DATASETS.build(data, frame=k).truth_T for k in range(3)]
    later = group(tiny_config(*FLICKER, f"phantom.time_s={1 / 24}", synthetic=False), "data")
    assert frames_of(later) is None  # no data.frames: one steady scene
    np.testing.assert_allclose(DATASETS.build(later).truth_T, T[1], atol=1e-6)
    assert np.abs(T[1] - T[0]).max() > 50.0
    np.testing.assert_allclose(T[2], T[0], atol=1e-6)


def test_a_steady_phantom_has_no_frames():
    data = group(tiny_config("data.frames=4"), "data")  # the tiny scene's Gaussian blob does not change in time
    with pytest.raises(ValueError, match="phantom 'gaussian_blob' does not change in time.*phantom=flicker"):
        frames_of(data)


def test_each_frame_has_noise_of_its_own():
    """A still phantom (no amplitude) over two frames: the same truth, but independent noise draws."""
    data = group(tiny_config(*FLICKER, "phantom.amplitude=0", "data.frames=2", "data.deflection_noise=0.1",
                             synthetic=False), "data")
    clean = DATASETS.build({**data, "deflection_noise": 0.0}, frame=0).eps
    a, b = ((DATASETS.build(data, frame=k).eps - clean) for k in (0, 1))
    rms = float(a.norm(dim=-1).pow(2).mean().sqrt())
    assert rms > 0 and float((a - b).norm(dim=-1).pow(2).mean().sqrt()) > rms  # uncorrelated: about sqrt(2) x
