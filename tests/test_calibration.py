"""An OpenCV calibration of the cameras (nerif.data.calibration, issue 29): its parts against closed forms and OpenCV,
and OpenCV's intrinsics, distortion and pose read from a version-3 capture."""
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from nerif.data.calibration import (PITCH_UM, calibrated_camera, calibration_entry, corner_distortion, plausible,
                                    read_calibration)
from nerif.data.capture import rig_cameras
from nerif.data.rig_file import RIG_FILE, read_rig
from nerif.geometry import ProbeBox, rays_in_box
from tests.helpers import shared_data

RIG = {"format": "nerif-capture", "version": 3, "calibration": "calibration.yml",
       "probe": {"shape": [60, 100, 60], "voxel_mm": 1.0}, "ambient": {"T0": 296.15, "n0": 1.00027}, "T_max": 2000.0,
       "heldout": [9]}


def multicam() -> Path:
    """``../shared/data/independent_capture_bunsen_multicam`` (the test is skipped where it is not there)."""
    return shared_data("independent_capture_bunsen_multicam")


def folder(tmp_path: Path, edit=None) -> Path:
    """The multicam capture with the issue's version-3 rig.yaml beside its files (calibration edited by ``edit``)."""
    tmp_path.mkdir(exist_ok=True)
    source = multicam()
    for f in source.iterdir():
        if f.suffix == ".png" or (f.name == "calibration.yml" and edit is None):
            (tmp_path / f.name).symlink_to(f)
    if edit is not None:
        text = (source / "calibration.yml").read_text()
        (tmp_path / "calibration.yml").write_text(edit(text))
    (tmp_path / RIG_FILE).write_text(yaml.safe_dump(RIG))
    return tmp_path


def test_a_pixels_ray_is_opencvs_and_projects_back_onto_the_pixel(tmp_path):
    fs = cv2.FileStorage(str(multicam() / "calibration.yml"), cv2.FILE_STORAGE_READ)
    full, _ = rig_cameras(read_rig(folder(tmp_path)), 1)
    rng = np.random.default_rng(0)
    for k, cam in enumerate(full):
        K, dist = fs.getNode(f"camera_{k:02d}_camera_matrix").mat(), fs.getNode(f"camera_{k:02d}_dist_coeffs").mat()
        rvec, tvec = fs.getNode(f"camera_{k:02d}_rvec").mat(), fs.getNode(f"camera_{k:02d}_tvec").mat()
        px = rng.uniform([0, 0], [cam.width, cam.height], (500, 2))  # ours: pixel centres at +0.5
        xy = cam.normalised(px)
        ocv = cv2.undistortPoints((px - 0.5).reshape(-1, 1, 2), K, dist).reshape(-1, 2)  # 5 iterations
        assert np.abs(xy - ocv).max() < 1e-5  # OpenCV's default stops short of our 1e-14
        world = cam.position + 700.0 * (np.concatenate([xy, np.ones((500, 1))], 1) @ cam.rotation.T)
        back = cv2.projectPoints(world, rvec, tvec, K, dist)[0].reshape(-1, 2) + 0.5
        assert np.abs(back - px).max() < 1e-6
        np.testing.assert_allclose(cam.project(world), back, atol=1e-9)  # our projection is OpenCV's
        # the ray through every pixel centre of the binned camera is the full sensor's ray through that point
        d = cam.binned(4).pixel_directions()
        centre = np.array([[4 * 10 + 2.0, 4 * 20 + 2.0]])  # pixel (10, 20) of the binned grid, on the full sensor
        ray = np.concatenate([cam.normalised(centre), [[1.0]]], 1) @ cam.rotation.T
        np.testing.assert_allclose(d[20 * (cam.width // 4) + 10].numpy(),
                                   ray[0] / np.linalg.norm(ray), atol=1e-12)


def test_the_rig_is_the_calibrations_and_sees_the_probe(tmp_path):
    rig = read_rig(folder(tmp_path))
    full, cams = rig_cameras(rig, 4)
    assert len(full) == 10 and rig.frames[0].images[3] == "distorted_03.png"
    assert rig.roi_px == (0, 0, 360, 640)
    for cam in full:  # 740-900 mm from the axis, within 35 mm of the probe's height, looking at its centre
        assert 740 - 1 < np.hypot(cam.position[0], cam.position[2]) < 900 + 1 and abs(cam.position[1]) < 36
        axis = cam.rotation[:, 2]
        miss = np.linalg.norm(np.cross(-cam.position, axis))  # distance of the centre from the optical axis
        assert miss < 10.0
    origins, dirs, pixel, starts = rays_in_box(ProbeBox((60, 100, 60), 1.0), cams)
    assert len(starts) == 11 and len(dirs) > 10 * 0.3 * 90 * 160


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("camera_03_rvec", "camera_03_rvex"), r"camera 03 \(camera_03_<key>\): 'rvec' must be 3 "),
    (lambda t: t.replace("camera_02_pixel_pitch_mm: 0.04", "camera_02_pixel_pitch_mm: -0.04"),
     r"camera 02 \(camera_02_<key>\): 'pixel_pitch_mm' must be a positive length"),
    (lambda t: t.replace("camera_05_background_distance_mm: ", "camera_05_background_distance_mm: 100 #"),
     "camera 05: its background, 100 mm away, is not behind the probe box"),
])
def test_a_bad_calibration_is_one_sentence_naming_the_camera_and_key_before_any_flow(tmp_path, monkeypatch, edit,
                                                                                     message):
    import nerif.data.capture as cap_mod

    def no_flow(*a, **k):
        raise AssertionError("the flow ran on a bad calibration")

    monkeypatch.setattr(cap_mod.FLOW, "build", no_flow)
    with pytest.raises(ValueError, match=message):
        cap_mod.capture(str(folder(tmp_path, edit)), {"name": "farneback"}, binning=4)


def test_the_keys_the_data_readme_lists_are_the_keys_nerif_reads():
    import re

    from nerif.data.calibration import CALIBRATION_KEYS

    listed = set(re.findall(r"camera_KK_(\w+)", (multicam() / "README.md").read_text()))
    assert listed == set(CALIBRATION_KEYS)
    fs = cv2.FileStorage(str(multicam() / "calibration.yml"), cv2.FILE_STORAGE_READ)
    assert all(not fs.getNode(f"camera_09_{k}").empty() for k in CALIBRATION_KEYS)


def test_a_calibrated_rig_reconstructs_within_a_bound_of_the_arc(tmp_path):
    """The same blob through an arc and through ``rig=calibrated`` (the same sensor, distances and span), ideal
    deflections, rays 1.5 mm apart at the probe: both reconstruct it (0.31 of sigma's norm measured for either;
    rays 6 mm apart left 0.9, nothing to compare) and the calibrated rig's error is within 1.3x the arc's (1.02x)."""
    from nerif.app import run
    from tests.helpers import tiny_config

    common = ["rig.n_cameras=6", "rig.span_deg=160", "rig.width_px=360", "rig.height_px=640", "rig.pitch_um=40",
              "rig.binning=5", "train.iterations=100", "train.eval_every=100", "data.sensing=perpendicular"]
    arc = run(tiny_config(*common, "rig.distance_mm=820", "rig.background_behind_mm=750"), tmp_path / "arc")
    cal = run(tiny_config("rig=calibrated", *common), tmp_path / "cal")
    assert arc["sigma_relative_error"] < 0.45, arc
    assert cal["sigma_relative_error"] < 1.3 * arc["sigma_relative_error"], (cal, arc)


def test_a_capture_written_through_a_calibrated_rig_reads_back_its_cameras_and_rays(tmp_path):
    """``write_capture`` of a scene seen by ``rig=calibrated`` (hand-placed cameras, principal points off centre,
    lens distortion) writes a version-3 folder with an OpenCV calibration; read back, every ray is the scene's."""
    import torch

    from nerif.configs import compose, group
    from nerif.data import DATASETS
    from nerif.data.capture import capture
    from nerif.write_capture import write_capture

    cfg = compose(["data.sensing=realistic", "rig=calibrated", "rig.n_cameras=4", "rig.binning=8",
                   "phantom=gaussian_blob", "phantom.shape=[16,16,16]", "phantom.voxel_mm=3.0", "phantom.width_mm=7.0",
                   "data.sensor.aperture_rays=4", "data.render_supersample=1", "data.cache_dir=null"])
    scene = DATASETS.build(group(cfg, "data"), device="cpu")
    root = write_capture(scene, tmp_path / "cap")
    assert yaml.safe_load((root / RIG_FILE).read_text())["version"] == 3
    cap = capture(str(root), {"name": "farneback"}, binning=8)
    assert cap.n_views == 3 and cap.heldout.n_views == 1
    for ours, theirs in zip(cap.cameras, scene.cameras):
        np.testing.assert_allclose(ours.position, theirs.position, atol=1e-9)
        np.testing.assert_allclose(ours.rotation, theirs.rotation, atol=1e-12)
        np.testing.assert_allclose(ours.principal_point, theirs.principal_point, atol=1e-9)
        np.testing.assert_allclose(ours.distortion, theirs.distortion, atol=1e-15)
        assert ours.principal_point != (ours.width / 2, ours.height / 2) and ours.distortion[0] != 0
    n = int(scene.view_start[3])
    assert torch.equal(cap.pixel, scene.pixel[:n]) and torch.allclose(cap.dirs, scene.dirs[:n], atol=1e-7)
    ref = scene.eps[:n]
    err = float((cap.eps - ref).norm(dim=-1).pow(2).mean().sqrt() / ref.norm(dim=-1).pow(2).mean().sqrt())
    assert err < 0.15, err  # the flow's error on 8-bit images


def test_a_cameras_list_in_the_rig_file_is_the_calibration_file(tmp_path):
    """Version 3 reads the cameras from ``rig.yaml``'s own ``cameras`` list as from an OpenCV calibration file."""
    fs = cv2.FileStorage(str(multicam() / "calibration.yml"), cv2.FILE_STORAGE_READ)
    cameras = []
    for k in range(10):
        get = lambda key: fs.getNode(f"camera_{k:02d}_{key}")  # noqa: E731
        cameras.append({"image": get("image").string(), "reference": get("reference").string(),
                        "image_size": get("image_size").mat().reshape(-1).tolist(),
                        "camera_matrix": get("camera_matrix").mat().tolist(),
                        "dist_coeffs": get("dist_coeffs").mat().reshape(-1).tolist(),
                        "rvec": get("rvec").mat().reshape(-1).tolist(), "tvec": get("tvec").mat().reshape(-1).tolist(),
                        "pixel_pitch_mm": get("pixel_pitch_mm").real(),
                        "background_distance_mm": get("background_distance_mm").real()})
    listed = tmp_path / "listed"
    listed.mkdir()
    for f in multicam().glob("*.png"):
        (listed / f.name).symlink_to(f)
    rig = {k: v for k, v in RIG.items() if k != "calibration"}
    (listed / RIG_FILE).write_text(yaml.safe_dump({**rig, "cameras": cameras}))
    a, b = rig_cameras(read_rig(listed), 4)[1], rig_cameras(read_rig(folder(tmp_path / "file")), 4)[1]
    for x, y in zip(a, b):
        assert np.array_equal(x.pixel_directions().numpy(), y.pixel_directions().numpy())
    for edit, message in [  # issue 38: values against what cameras and lenses have
        (lambda c: c.update(dist_coeffs=[0.1, "x"]), r"'dist_coeffs' must be"),
        (lambda c: c.update(rvec=np.rad2deg(c["rvec"]).tolist()), r"'rvec' turns by .*more than pi: .*in degrees\?"),
        (lambda c: c.update(dist_coeffs=[50.0, 0, 0, 0, 0]), r"'dist_coeffs' .* move the image's corner by \d+ %"),
        (lambda c: c.update(pixel_pitch_mm=40.0), r"'pixel_pitch_mm' x 1000 \[um\] = 40000 is outside what cameras "
                                                  r"have .*a pitch in nanometres"),
        (lambda c: c.update(background_distance_mm=1.6), r"'background_distance_mm' = 1.6 .*a distance in metres"),
    ]:
        bad = [dict(c) for c in cameras]
        edit(bad[4])
        (listed / RIG_FILE).write_text(yaml.safe_dump({**rig, "cameras": bad}))
        with pytest.raises(ValueError, match=r"rig.yaml: cameras\[4\]: " + message):
            read_rig(listed)


# --- the module's parts on their own, without the shared capture ---


K0 = np.array([[2600.0, 0.0, 179.5], [0.0, 2610.0, 320.0], [0.0, 0.0, 1.0]])


def entry(**changes) -> dict:
    values = {"image": "distorted_00.png", "reference": "reference_00.png", "image_size": [360, 640],
              "camera_matrix": K0, "dist_coeffs": [-0.08, 0.02, 1e-4, -2e-4, 0.0], "rvec": [0.02, -0.3, 0.01],
              "tvec": [5.0, -3.0, 800.0], "pixel_pitch_mm": 0.04, "background_distance_mm": 1600.0}
    values.update(changes)
    return values


def test_corner_distortion_is_the_radial_factors_closed_form():
    """k1 alone moves a point at r by k1 r^3: the share k1 r^2 at the farthest corner."""
    w, h = 360, 640
    K = np.array([[1000.0, 0, 180], [0, 1000.0, 320], [0, 0, 1]])
    r2 = (180**2 + 320**2) / 1000.0**2
    assert corner_distortion(K, np.array([0.1, 0, 0, 0, 0]), (w, h)) == pytest.approx(0.1 * r2, rel=1e-12)
    assert corner_distortion(K, np.array([0.1, 0.05, 0, 0, 0.01]), (w, h)) == pytest.approx(
        0.1 * r2 + 0.05 * r2**2 + 0.01 * r2**3, rel=1e-12)
    assert corner_distortion(K, np.zeros(5), (w, h)) == 0.0
    assert corner_distortion(K, np.array([-10.0, 0, 0, 0, 0]), (w, h)) == float("inf")  # folds the image over


def test_a_value_in_another_unit_names_the_unit():
    assert plausible(5.5, PITCH_UM, "pitch") == 5.5
    with pytest.raises(ValueError, match=r"a pitch in millimetres\? 0.0055 mm is 5.5 um"):
        plausible(0.0055, PITCH_UM, "pitch")


@pytest.mark.parametrize("change, message", [
    ({"camera_matrix": np.eye(3) * [[-1], [1], [1]]}, "fx, fy > 0"),
    ({"dist_coeffs": [0.1, 0.2]}, "'dist_coeffs' must be"),
    ({"dist_coeffs": [20.0, 0, 0, 0, 0]}, "move the image's corner by"),
    ({"rvec": [0, 90, 0]}, "in degrees\\?"),
    ({"tvec": [1, 2]}, "'tvec' must be 3 finite numbers"),
    ({"pixel_pitch_mm": -0.04}, "'pixel_pitch_mm' must be a positive length"),
    ({"background_distance_mm": 1.6}, "a distance in metres"),
    ({"image": ""}, "lacks 'image'"),
])
def test_a_bad_entry_is_one_sentence_naming_the_camera_and_key(change, message):
    with pytest.raises(ValueError, match=message) as e:
        calibration_entry(entry(**change), "camera 03", "cal.yml: camera 03")
    assert str(e.value).startswith("cal.yml: camera 03")


def test_a_calibration_file_reads_back_as_written_and_its_camera_projects_as_opencvs(tmp_path):
    path = tmp_path / "calibration.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("n_cameras", 1)
    for key, v in entry().items():
        fs.write(f"camera_00_{key}", np.asarray(v, np.float64) if not isinstance(v, (str, float)) else v)
    fs.release()
    (c,) = read_calibration(path)
    assert c["name"] == "camera 00" and c["size"] == (360, 640) and c["pixel_pitch_mm"] == 0.04
    cam = calibrated_camera(c, f_number=8.0)
    points = np.random.default_rng(0).uniform(-30, 30, (50, 3))
    opencv, _ = cv2.projectPoints(points, c["rvec"], c["tvec"], c["K"], c["dist"])
    # nerif counts a pixel's centre at +0.5 (its corner at 0), OpenCV at 0
    assert np.allclose(cam.project(points), opencv[:, 0] + 0.5, atol=1e-6)
    # in focus on the background: the thin lens of the image distance fx * pitch and the background's distance
    s_i = 2600.0 * 0.04
    assert cam.focal_mm == pytest.approx(1 / (1 / s_i + 1 / 1600.0))


def test_a_file_without_cameras_is_one_sentence(tmp_path):
    path = tmp_path / "empty.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("something", 1)
    fs.release()
    with pytest.raises(ValueError, match="lacks 'n_cameras'"):
        read_calibration(path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        read_calibration(tmp_path / "missing.yml")
