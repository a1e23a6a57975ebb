"""The paper's dataset format: geometry and channel order of the importer, on the authors' Phantom 1 data."""
import numpy as np
import pytest
import torch

from nerif.data.transforms import load_views, optics, read_frame, read_split, reference_mask3d, transforms
from nerif.geometry import ProbeBox
from nerif.masks.backprojection import back_project
from nerif.physics import Ambient
from tests.helpers import shared_data

BOX = ProbeBox((140, 294, 140), 0.5)
PROBE = {"shape": [140, 294, 140], "voxel_mm": 0.5}


@pytest.fixture(scope="module")
def phantom1():
    """The authors' Phantom 1 data (``../shared/data/nirbos_phantom1``)."""
    return shared_data("nirbos_phantom1")


@pytest.fixture(scope="module")
def frames(phantom1):
    """The two val views at full resolution, as the importer reads them."""
    meta = read_split(phantom1, "val")
    return [read_frame(phantom1, "val", meta, k, optics()) for k in range(len(meta["frames"]))]


def test_probe_centre_projects_inside_the_masks(frames):
    for cam, _, roi, mask in frames:
        col, row = np.floor(cam.project(np.zeros(3))).astype(int)
        assert mask[row, col] and roi[row, col], cam.name
        # the camera looks at the probe from 800 mm
        assert np.linalg.norm(cam.position) == pytest.approx(800.0, rel=1e-6)


def _along_ray(cam, eps, where) -> float:
    """rms of eps . d over rms |eps|, on the pixels ``where``."""
    d = cam.pixel_directions(torch.float64).numpy().reshape(cam.height, cam.width, 3)[where]
    e = eps[where]
    return float(np.sqrt(((e * d).sum(-1) ** 2).sum() / (e ** 2).sum()))


def test_deflections_perpendicular_to_the_importers_rays(frames):
    for cam, eps, roi, mask in frames:
        where = mask & roi
        # the authors store vectors perpendicular to the camera axis: within 1e-3 of it (16-bit quantisation)
        axis = np.asarray(cam.rotation)[:, 2]
        assert np.sqrt(((eps[where] @ axis) ** 2).sum() / (eps[where] ** 2).sum()) < 1e-3
        # so against each ray they are off by the ray's angle to the axis at most (< 0.06 rad here)
        assert _along_ray(cam, eps, where) < 0.04
    # the second val view is 15 degrees off the z axis: swapping eps_x and eps_z (a wrong channel order) breaks it
    cam, eps, roi, mask = frames[1]
    assert _along_ray(cam, eps[..., ::-1], mask & roi) > 0.3


def test_deflections_point_out_of_the_hot_flame(frames):
    """sum over a view of eps . r (r: offset of the ray from the flame axis, perpendicular to the ray) is
    -integral of the projected sigma over the image, > 0 for a flame hotter than ambient. A mirrored pose
    (image columns read left to right) flips r and the sign."""
    for cam, eps, roi, mask in frames:
        where = mask & roi
        d = cam.pixel_directions(torch.float64).numpy().reshape(cam.height, cam.width, 3)[where]
        o = np.asarray(cam.position)
        # closest point of each ray to the vertical axis x = z = 0, horizontal offset from it
        t = -(o[0] * d[:, 0] + o[2] * d[:, 2]) / (d[:, 0] ** 2 + d[:, 2] ** 2)
        p = o + t[:, None] * d
        r = p * np.array([1.0, 0.0, 1.0])
        score = (eps[where] * r).sum() / (np.linalg.norm(eps[where], axis=-1) * np.linalg.norm(r, axis=-1)).sum()
        assert score > 0.2, (cam.name, score)


def test_scene_from_the_importer(phantom1):
    scene = transforms(str(phantom1), PROBE, 1100.0, 1.00007253, sigma_prior=None, binning=8, heldout_split="val")
    assert scene.n_views == 12 and scene.heldout.n_views == 2
    assert not scene.ambient.temperature_known and scene.ambient.delta_thre == 1.0
    assert scene.perpendicular_only and scene.mask_images[0].shape == (160, 90)
    # stored perpendicular to the rays; values in sigma units (|eps| up to ~17)
    assert float((scene.eps * scene.dirs).sum(-1).abs().max()) < 1e-5
    assert 10.0 < float(scene.eps.norm(dim=-1).max()) < 20.0
    # every kept ray lies inside its view's UVROI (1-based [u, v, w, h]; view 0: [103, 100, 515, 1081])
    cam = scene.cameras[0]
    sl = scene.view_slice(0)
    col, row = scene.pixel[sl] % cam.width, scene.pixel[sl] // cam.width
    assert int(col.min()) * 8 >= 102 and (int(col.max()) + 1) * 8 <= 102 + 515
    assert int(row.min()) * 8 >= 99 and (int(row.max()) + 1) * 8 <= 99 + 1081


def test_training_views_held_out_as_novel_views(phantom1):
    scene = transforms(str(phantom1), PROBE, 1100.0, 1.00007253, sigma_prior=None, binning=8, heldout_split=None, heldout_views=[3])
    assert scene.n_views == 11 and scene.heldout.n_views == 1
    assert np.allclose(scene.heldout.cameras[0].position, [-565.685, 0.0, -565.685], atol=1e-3)  # 45 degrees
    assert len(scene.mask_images) == 11
    with pytest.raises(ValueError, match="heldout_split=null"):
        transforms(str(phantom1), PROBE, 1100.0, 1.00007253, sigma_prior=None, binning=8, heldout_views=[3])


def test_masks_back_project_onto_the_authors_3d_mask(phantom1):
    """Our visual hull of their 2-D masks against their 3-D mask, both sampled at 1 mm (IoU 0.908; 0.918 on the
    0.5 mm probe grid, 9x the time)."""
    scene = load_views(phantom1, "train", BOX, Ambient(1100.0, 1.00007253, None), optics(), binning=8)
    coarse = ProbeBox(tuple(n // 2 for n in BOX.shape), 2 * BOX.voxel_mm)  # the same box in 1 mm voxels
    ours = back_project(coarse, scene.cameras, scene.mask_images)
    theirs = reference_mask3d(str(phantom1), coarse)
    iou = (ours & theirs).sum() / (ours | theirs).sum()
    assert iou > 0.85, iou


def test_bad_dataset_folders(tmp_path):
    with pytest.raises(FileNotFoundError, match="transforms_train.json"):
        transforms(str(tmp_path), PROBE, 1100.0, 1.00007253, sigma_prior=None)
    with pytest.raises(FileNotFoundError, match="not a folder"):
        transforms(str(tmp_path / "nope"), PROBE, 1100.0, 1.00007253, sigma_prior=None)
    with pytest.raises(ValueError, match="data.root is not set"):
        transforms("???", PROBE, 1100.0, 1.00007253, sigma_prior=None)


@pytest.mark.parametrize("edit, message", [
    ({"image_max": -16.8897858}, r"image_max \(-16.8897858\) must exceed image_min"),  # equal to image_min
    ({"fl_x": -1000.0}, r"the focal length fl_x = -1000.0 px must be positive"),
    ({"w": 721}, r"images are 720 x 1280 px, the json's w and h say 721 x 1280"),  # not blamed on the binning
    ({"frames": {"a": 1}}, r"frames must be a list \(one entry per view\), not a dict"),
    ({"frames": [{"transform_matrix": [[1, 0, 0, 0]] * 4}]}, r"frame 0 lacks file_path, mask_file_path"),
    ("{", r"transforms_train.json is not valid JSON \(line 1\)"),
])
def test_a_bad_transforms_file_is_one_sentence_naming_it(phantom1, tmp_path, edit, message):
    """Issue 28: image_min == image_max trained on constant deflections; a negative fl_x gave 4.2 against 0.73; a
    truncated file, frames as a dict or without file_path were tracebacks; a wrong w was blamed on the binning."""
    import json

    for split in ("train", "val", "test"):
        meta = json.loads((phantom1 / f"transforms_{split}.json").read_text())
        text = edit if isinstance(edit, str) else json.dumps({**meta, **edit})
        (tmp_path / f"transforms_{split}.json").write_text(text)
        (tmp_path / split).symlink_to(phantom1 / split)
    with pytest.raises(ValueError, match=message):
        transforms(str(tmp_path), PROBE, 1100.0, 1.00007253, sigma_prior=None)
