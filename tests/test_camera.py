"""Cameras and rigs: the paper's arc, pixel rays, binning, NeRF poses."""
import numpy as np
import pytest

from nerif.geometry import arc_rig


def test_arc_rig_matches_the_paper_geometry():
    cams = arc_rig(binning=1)
    assert len(cams) == 12
    # cameras 800 mm from the centre, 15 degrees apart, camera 0 on +z, camera 6 at 90 degrees on +x
    np.testing.assert_allclose([np.linalg.norm(c.position) for c in cams], 800.0)
    np.testing.assert_allclose(cams[0].position, [0, 0, 800], atol=1e-9)
    np.testing.assert_allclose(cams[11].position / 800, [np.sin(np.deg2rad(165)), 0, np.cos(np.deg2rad(165))])
    # 105 mm lens focused 1600 mm away: image distance 112.37 mm (the paper data's fl = 5618.73 px of 20 um)
    assert cams[0].image_distance_mm / 0.020 == pytest.approx(5618.73, rel=1e-5)
    for cam in cams:
        np.testing.assert_allclose(cam.project(np.zeros(3)), [360.0, 640.0], atol=1e-9)
        # image rows run down the world y axis
        assert cam.project(np.array([0.0, 10.0, 0.0]))[1] < 640.0


def test_pixel_directions_project_back_to_their_pixels():
    cam = arc_rig(n_cameras=3, binning=16)[1]
    d = cam.pixel_directions().numpy()
    pts = cam.position + 700.0 * d
    uv = cam.project(pts)
    j, i = np.divmod(np.arange(cam.width * cam.height), cam.width)
    np.testing.assert_allclose(uv, np.stack([i + 0.5, j + 0.5], -1), atol=1e-6)


def test_binning_must_divide_the_sensor():
    with pytest.raises(ValueError, match="binning 7"):
        arc_rig(binning=7)


def test_camera_from_nerf_pose():
    from nerif.geometry import camera_from_nerf_pose

    kw = dict(pitch_mm=0.02, length_mm=0.02, f_number=8.0, background_mm=10.0, focal_mm=2.0)
    c2w = np.eye(4)
    c2w[2, 3] = 250.0  # 5 mm in pixel-pitch units; OpenGL camera looking along -z at the origin
    cam = camera_from_nerf_pose(c2w, 100.0, 64, 48, 32.0, 24.0, **kw)
    assert np.allclose(cam.position, [0, 0, 5]) and cam.image_distance_mm == pytest.approx(2.0)
    assert np.allclose(cam.rotation, np.diag([1.0, -1.0, -1.0]))  # right +x, image rows down = -y, forward -z
    # a point 1 mm right of and 1 mm above the axis, 5 mm in front: 100 px * 1/5 right, and up in the image
    assert np.allclose(cam.project(np.array([1.0, 1.0, 0.0])), [52.0, 4.0])
    # a reflected pose (det -1, the BOS paper's datasets) is read with its right axis negated: a proper rotation
    refl = c2w.copy()
    refl[:3, 0] *= -1
    assert np.allclose(camera_from_nerf_pose(refl, 100.0, 64, 48, 32.0, 24.0, **kw).rotation, cam.rotation)
    with pytest.raises(ValueError, match="principal point"):
        camera_from_nerf_pose(c2w, 100.0, 64, 48, 30.0, 24.0, **kw)
    bad = c2w.copy()
    bad[0, 3] = np.nan
    with pytest.raises(ValueError, match=r"the pose is not finite \(1 NaN or infinite entries\)"):
        camera_from_nerf_pose(bad, 100.0, 64, 48, 32.0, 24.0, **kw)
    with pytest.raises(ValueError, match="must be a 4 x 4 or 3 x 4 matrix, got shape"):
        camera_from_nerf_pose(np.eye(3), 100.0, 64, 48, 32.0, 24.0, **kw)


def test_arc_rig_at_given_angles_and_binning_is_recorded():
    cams = arc_rig(angles_deg=[0.0, -90.0], binning=8)
    assert len(cams) == 2 and np.allclose(cams[1].position, [-800.0, 0.0, 0.0], atol=1e-9)
    assert cams[0].binning == 8 and cams[0].unbinned(8).binning == 1 and cams[0].unbinned(8).width == 720


def test_pixels_per_mm_is_the_image_scale_across_the_line_of_sight():
    cam = arc_rig(n_cameras=3, binning=4)[1]
    point = np.array([3.0, -5.0, 2.0])
    across = np.cross(cam.rotation[:, 2], [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    uv = cam.project(np.stack([point - 0.05 * across, point + 0.05 * across]))
    assert cam.pixels_per_mm(point) == pytest.approx(np.linalg.norm(uv[1] - uv[0]) / 0.1, rel=1e-3)
    assert cam.binned(2).pixels_per_mm(point) == pytest.approx(cam.pixels_per_mm(point) / 2)


def test_the_rig_axis_is_the_normal_of_the_plane_its_views_turn_in_pointing_up():
    """An arc turns about +y; the same arc rotated about x by 35 degrees turns about the rotated y (sign kept up),
    whatever the order of its views."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from nerif.geometry import arc_rig, rig_axis

    np.testing.assert_allclose(rig_axis(arc_rig(9, 120.0)), [0.0, 1.0, 0.0], atol=1e-12)
    turn = Rotation.from_euler("x", 35, degrees=True).as_matrix()
    cams = [replace(c, rotation=turn @ np.asarray(c.rotation)) for c in arc_rig(9, 160.0)[::-1]]
    np.testing.assert_allclose(rig_axis(cams), turn @ [0.0, 1.0, 0.0], atol=1e-12)
