import logging

import numpy as np
import pytest
import torch

from nerif.data import DATASETS
from nerif.data.folders import finite_or_masked

BLOB = {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0, "width_mm": 5.0}
RIG = {"name": "arc", "n_cameras": 3, "binning": 40}


REALISTIC = {"name": "synthetic", "render_supersample": 1, "phantom": BLOB, "rig": dict(RIG, n_cameras=2), "T_max": 2000.0, "sensing": "realistic",
             "sensor": {"aperture_rays": 8, "noise_variance": 1e-4, "image_binning": 8, "seed": 0,
                        "pattern": {"name": "poisson_disk"}, "flow": {"name": "farneback"}}}


def test_flow_failures_are_left_out_and_said_never_propagated(monkeypatch, caplog):
    from nerif.sensing.flow import FLOW

    def half_nan(distorted, reference):  # Farneback's flow without its upper half (it passes the flow's own check)
        u = FLOW.build({"name": "farneback"}, distorted=distorted, reference=reference)
        u[: u.shape[0] // 2] = np.nan
        return u

    monkeypatch.setitem(FLOW._entries, "half_nan", half_nan)
    with caplog.at_level("INFO"):
        s = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], flow={"name": "half_nan"})))
    assert caplog.text.count("50.0 % unmeasured") >= 2  # each view says it, as a capture's do
    assert torch.isfinite(s.eps).all() and 0 < len(s.eps) < 2 * 18 * 32
    assert int(s.view_start[-1]) == len(s.dirs) == len(s.pixel)
    rows = s.pixel // 18
    assert bool((rows >= 16).all())  # only the lower half of each image, where the flow was finite


def test_split_views_moves_whole_views_to_the_held_out_scene():
    scene = DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": {"name": "arc", "n_cameras": 4, "binning": 40},
                            "T_max": 2000.0, "render_supersample": 1})
    train = scene.split_views([2])
    assert train.n_views == 3 and train.heldout.n_views == 1 and train.heldout.heldout is None
    assert train.heldout.cameras[0] is scene.cameras[2]
    torch.testing.assert_close(train.heldout.eps, scene.eps[scene.view_slice(2)])
    torch.testing.assert_close(train.eps[train.view_slice(2)], scene.eps[scene.view_slice(3)])
    torch.testing.assert_close(train.origins, scene.origins[[0, 1, 3]])
    assert int(train.view_start[-1]) + int(train.heldout.view_start[-1]) == len(scene.dirs)
    with pytest.raises(ValueError, match="at least one must be trained on"):
        scene.split_views([0, 1, 2, 3])
    with pytest.raises(ValueError, match="within 0..3"):
        scene.split_views([4])


def test_non_finite_estimates_are_masked_and_said(caplog):
    u = np.zeros((4, 5, 2), np.float32)
    u[1, 2, 0], u[3, 4, 1] = np.nan, np.inf
    with caplog.at_level(logging.INFO):
        ok = finite_or_masked(u, "view 3")
    assert ok.sum() == 18 and not ok[1, 2] and not ok[3, 4]
    assert "view 3: 2 of 20 displacement estimates are left out" in caplog.text


def test_distinct_view_directions():
    from nerif.data.diagnostics import view_directions
    from nerif.geometry.camera import arc_rig

    assert view_directions(arc_rig(n_cameras=12)) == 12
    assert view_directions(arc_rig(angles_deg=[30.0, 30.0, 30.0])) == 1  # three views at one angle
    assert view_directions(arc_rig(angles_deg=[0.0, 180.0, 90.0, 90.5])) == 2  # opposite and near views are one


def test_held_out_views_given_as_a_number_are_one_sentence_naming_the_setting():
    """Issue 38: ``data.heldout=8`` (a number where a list goes) was a TypeError traceback."""
    from nerif.data.scene import heldout_views

    assert heldout_views([3.0, 1], 5, "data.heldout") == [1, 3]
    with pytest.raises(ValueError, match=r"data.heldout=3 must be a list of view indices, such as \[3\]"):
        heldout_views(3, 5, "data.heldout")
    with pytest.raises(ValueError, match=r"data.heldout=\['a'\] must be a list of view indices"):
        heldout_views(["a"], 5, "data.heldout")
    with pytest.raises(ValueError, match=r"data.heldout \[7\] must be within 0..4"):
        heldout_views([7], 5, "data.heldout")
