"""Camera rays through the probe box."""
import numpy as np
import pytest

from nerif.geometry import Camera, ProbeBox, arc_rig, look_at_origin, rays_in_box


def test_a_camera_that_does_not_see_the_box_is_named():
    box = ProbeBox((10, 10, 10), 1.0)
    good = arc_rig(n_cameras=1, binning=40)[0]
    pos = np.array([0.0, 0.0, 800.0])
    away = Camera(pos, look_at_origin(-pos) @ np.diag([1.0, 1.0, 1.0]), 112.4, 0.8, 18, 32, 32.0, 1600, 105,
                  name="camera 7 (backwards)")
    with pytest.raises(ValueError, match="camera 7 \\(backwards\\) .* does not see the probe box"):
        rays_in_box(box, [good, away])


@pytest.mark.parametrize("kwargs, message", [
    ({"background_behind_mm": -200.0}, r"rig.background_behind_mm=-200.0 must be a positive number"),
    ({"focal_mm": -105.0}, r"rig.focal_mm=-105.0 must be a positive number"),
    ({"distance_mm": -800.0}, r"rig.distance_mm=-800.0 must be a positive number"),
    ({"pitch_um": 0.0}, r"rig.pitch_um=0.0 must be a positive number"),
])
def test_impossible_rig_settings_are_refused_naming_the_key(kwargs, message):
    """Issue 28: a background before the probe, a negative focal length or distance gave 400-700 K off."""
    with pytest.raises(ValueError, match=message):
        arc_rig(n_cameras=3, binning=40, **kwargs)


def test_a_camera_inside_the_box_or_a_background_before_its_far_side_is_refused():
    box = ProbeBox((100, 100, 100), 1.0)
    with pytest.raises(ValueError, match="camera 00 .* is inside the probe box"):
        rays_in_box(box, arc_rig(n_cameras=1, distance_mm=30.0, background_behind_mm=800.0, binning=40))
    with pytest.raises(ValueError, match="its background, 820 mm away, is not behind the probe box .* 850 mm away"):
        rays_in_box(box, arc_rig(n_cameras=1, distance_mm=800.0, background_behind_mm=20.0, binning=40))


def test_a_rotation_that_is_not_one_is_refused():
    R = look_at_origin(np.array([0.0, 0.0, 800.0])) @ np.diag([-1.0, 1.0, 1.0])  # a reflection
    with pytest.raises(ValueError, match="camera 3: its rotation is not a rotation"):
        Camera(np.array([0.0, 0.0, 800.0]), R, 112.4, 0.8, 18, 32, 32.0, 1600, 105, name="camera 3")


@pytest.mark.parametrize("voxel_mm, binning", [(1.0, 4), (0.5, 2), (3.0, 10), (0.1, 1)])
def test_the_automatic_binning_puts_about_one_ray_per_voxel(voxel_mm, binning):
    """A camera 800 mm from the probe centre, focused on a background 800 mm behind it, images 1 mm there onto
    f_img / (pitch 800 mm) = 112.37 / 32 = 3.51 pixels of 40 um (f_img = 1 / (1/105 - 1/1600) mm); the binning is the
    divisor of 360 and 640 nearest in ratio to the pixels a voxel spans: 3.51 -> 4, 1.76 -> 2, 10.5 -> 10, 0.35 -> 1."""
    from nerif.geometry import ray_binning

    cams = arc_rig(angles_deg=[0.0, 60.0, 120.0], distance_mm=800.0, focal_mm=105.0, width_px=360, height_px=640,
                   pitch_um=40.0, background_behind_mm=800.0, f_number=32.0, binning=1)
    assert cams[0].pixels_per_mm(np.zeros(3)) == pytest.approx(1 / (1 / 105 - 1 / 1600) / 32.0, rel=1e-9)
    assert ray_binning(cams, ProbeBox((10, 10, 10), voxel_mm)) == binning


def test_a_sensor_no_block_fits_is_said_to_be_binned_far_from_a_voxel(caplog):
    """A 361 x 641 px sensor divides only by 1: rays of 1 pixel where a voxel spans 3.5 is said, with the fix."""
    from nerif.data.folders import resolve_binning

    cams = arc_rig(angles_deg=[0.0, 60.0, 120.0], distance_mm=800.0, focal_mm=105.0, width_px=361, height_px=641,
                   pitch_um=40.0, background_behind_mm=800.0, f_number=32.0, binning=1)
    assert resolve_binning("auto", cams, ProbeBox((10, 10, 10), 1.0), "the sensor size 361 x 641 px") == 1
    assert "divides the sensor size 361 x 641 px, but a voxel spans 3.5 pixels; set data.binning" in caplog.text
    caplog.clear()
    fits = arc_rig(angles_deg=[0.0, 60.0], distance_mm=800.0, focal_mm=105.0, width_px=360, height_px=640,
                   pitch_um=40.0, background_behind_mm=800.0, f_number=32.0, binning=1)
    assert resolve_binning("auto", fits, ProbeBox((10, 10, 10), 1.0), "the sensor") == 4 and "WARNING" not in caplog.text


def test_rays_coarser_than_the_probe_grid_are_said_and_a_whole_float_is_a_binning(caplog):
    """Issue 38: ``data.binning=40`` (9 x 16 rays a view) gave 4.1x the error without a word, and ``4.0`` was
    refused. A voxel spans 3.5 pixels here: 8 x 8 pixels a ray (2.3 voxels) pass, 10 x 10 (2.8) are said."""
    from nerif.data.folders import resolve_binning

    cams = arc_rig(angles_deg=[0.0, 60.0], distance_mm=800.0, focal_mm=105.0, width_px=360, height_px=640,
                   pitch_um=40.0, background_behind_mm=800.0, f_number=32.0, binning=1)
    box = ProbeBox((10, 10, 10), 1.0)
    assert resolve_binning(4.0, cams, box, "the sensor") == 4
    assert resolve_binning(8, cams, box, "the sensor") == 8 and "WARNING" not in caplog.text
    assert resolve_binning(10, cams, box, "the sensor") == 10
    assert "data.binning=10: a ray spans 2.8 voxels of the probe grid across (36 x 64 rays a view)" in caplog.text
    assert "(auto: 4)" in caplog.text
    with pytest.raises(ValueError, match="data.binning=4.5: auto or a whole number"):
        resolve_binning(4.5, cams, box, "the sensor")


def test_the_pixels_outside_the_box_are_those_whose_ray_misses_it():
    """A small box at the centre of a camera's view: its centre pixel sees it, the corners do not, and the count
    of pixels outside is the sensor's less the rays that cross it."""
    from nerif.geometry import ProbeBox, arc_rig, outside_the_box, rays_in_box

    box = ProbeBox((8, 8, 8), 2.0)
    cams = arc_rig(n_cameras=2, binning=40)
    rays = rays_in_box(box, cams)
    quiet = outside_the_box(cams, rays[2], rays[3])
    for v, (cam, q) in enumerate(zip(cams, quiet)):
        assert q.shape == (cam.height, cam.width)
        assert not q[cam.height // 2, cam.width // 2] and q[0, 0] and q[-1, -1]
        assert int((~q).sum()) == int(rays[3][v + 1] - rays[3][v])
