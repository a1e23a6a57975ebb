import warnings

import numpy as np
import pytest

from nerif.data import DATASETS
from nerif.masks import MASKS
from nerif.masks.backprojection import back_project, deflection_masks

SPHERE = {"name": "gaussian_blob", "shape": [24, 24, 24], "voxel_mm": 2.0, "width_mm": 5.0, "T_peak": 1500.0}


@pytest.fixture(scope="module")
def scene():
    return DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                           "T_max": 2000.0})


def test_3d_mask_contains_the_blob_and_lies_inside_the_visual_hull(scene):
    masks = MASKS.build({"name": "3d", "threshold": 1e-3, "radius_px": 2}, scene=scene)
    flame = scene.truth_T - scene.ambient.T0 > 10.0
    assert flame.sum() > 50 and masks.volume[flame].all()
    # every valid voxel projects inside every view's 2-D mask (visual hull)
    centres = scene.box.centres()[masks.volume]
    for cam, img in zip(scene.cameras, masks.images):
        uv = np.floor(cam.project(centres)).astype(int)
        assert img[uv[:, 1], uv[:, 0]].all()
    assert masks.volume.mean() < 0.5  # it does cut away empty space


def test_fewer_cameras_required_only_grows_the_mask(scene):
    images = deflection_masks(scene, 1e-3, 2)
    sizes = [back_project(scene.box, scene.cameras, images, n).sum() for n in (6, 5, 3, 1)]
    assert sizes == sorted(sizes) and sizes[-1] > sizes[0]
    a, b = (back_project(scene.box, scene.cameras, images, n) for n in (6, 4))
    assert not (a & ~b).any()


def test_2d_masks_fill_the_quiet_core_of_a_symmetric_flame(scene):
    img = deflection_masks(scene, 1e-3, 0)[0]
    cam = scene.cameras[0]
    u, v = np.floor(cam.project(np.zeros(3))).astype(int)
    assert img[v, u]  # the central ray is barely deflected but lies inside the silhouette


def test_a_view_with_no_signal_warns_and_gets_an_empty_mask(scene):
    quiet = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                            "T_max": 2000.0})
    sl = slice(int(quiet.view_start[2]), int(quiet.view_start[3]))
    quiet.eps[sl] = 0.0
    with pytest.warns(UserWarning, match="camera 2 .* 2-D mask is empty"):
        masks = MASKS.build({"name": "2d", "threshold": 1e-3, "radius_px": 2}, scene=quiet)
    assert len(masks.inside[2]) == 0


def test_an_empty_3d_mask_is_a_clear_error(scene):
    silent = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                             "T_max": 2000.0})
    silent.eps.zero_()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match="3-D mask is empty"):
            MASKS.build({"name": "3d"}, scene=silent)
