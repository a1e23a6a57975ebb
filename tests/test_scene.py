import numpy as np
import pytest
import torch

from nerif.data import DATASETS
from nerif.data.scene import rays_in_box
from nerif.geometry import Camera, ProbeBox, arc_rig, look_at_origin

BLOB = {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0, "width_mm": 5.0}
RIG = {"n_cameras": 3, "binning": 40}


def test_synthetic_scene_keeps_only_rays_through_the_box_and_caches(tmp_path):
    scene = DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0,
                            "render_supersample": 2, "cache_dir": str(tmp_path)})
    assert scene.n_views == 3 and scene.view_start[-1] == len(scene.dirs) == len(scene.eps)
    o = scene.origins[scene.ray_views()]
    assert bool(scene.box.intersect(o, scene.dirs)[2].all())
    assert len(list(tmp_path.glob("synthetic-*.pt"))) == 1
    again = DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0,
                            "render_supersample": 2, "cache_dir": str(tmp_path)})
    torch.testing.assert_close(again.eps, scene.eps)
    # the pixel index addresses the ray's own pixel
    cam = scene.cameras[1]
    sl = slice(int(scene.view_start[1]), int(scene.view_start[2]))
    torch.testing.assert_close(scene.dirs[sl], cam.pixel_directions()[scene.pixel[sl]].float())


def test_a_camera_that_does_not_see_the_box_is_named():
    box = ProbeBox((10, 10, 10), 1.0)
    good = arc_rig(n_cameras=1, binning=40)[0]
    pos = np.array([0.0, 0.0, 800.0])
    away = Camera(pos, look_at_origin(-pos) @ np.diag([1.0, 1.0, 1.0]), 112.4, 0.8, 18, 32, 32.0, 1600, 105,
                  name="camera 7 (backwards)")
    with pytest.raises(ValueError, match="camera 7 \\(backwards\\) .* does not see the probe box"):
        rays_in_box(box, [good, away])


def test_supersampling_needs_a_phantom_with_a_grid(tmp_path):
    np.save(tmp_path / "T.npy", np.full((8, 8, 8), 400.0))
    ph = {"name": "file", "path": str(tmp_path / "T.npy"), "voxel_mm": 2.0, "T0": 296.15, "n0": 1.00027}
    with pytest.raises(ValueError, match="render_supersample=1"):
        DATASETS.build({"name": "synthetic", "phantom": ph, "rig": RIG, "T_max": 2000.0, "render_supersample": 2})
    scene = DATASETS.build({"name": "synthetic", "phantom": ph, "rig": RIG, "T_max": 2000.0})
    assert scene.truth_T.shape == (8, 8, 8)


def test_unknown_sensing_is_refused():
    with pytest.raises(ValueError, match="sensing"):
        DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0, "sensing": "magic"})
