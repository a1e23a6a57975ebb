import numpy as np
import pytest
import torch

from nerif.data.phantoms import PHANTOMS
from nerif.geometry import arc_rig
from nerif.renderers.voxel import voxel_deflection
from nerif.sensing.optics import aperture_points, aperture_rays, circle_of_confusion
from nerif.sensing.realistic import aperture_deflection


def test_circle_of_confusion_of_the_paper_rig_matches_the_hand_computation():
    cam = arc_rig(binning=1)[4]  # 105 mm lens, f/32, probe 800 mm away, background 1600 mm, 20 um pixels
    # by hand: s_i = 1 / (1/105 - 1/1600) = 112.37458 mm, M = s_i / 1600 = 0.0702341, aperture 105/32 = 3.28125 mm,
    # d_geo = 3.28125 * 0.0702341 * 800 / 800 = 0.230456 mm; d_diff = 2.44 * 0.5e-3 * 32 * 1.0702341 = 0.0417819 mm
    c = circle_of_confusion(cam)
    assert c["d_geo_mm"] == pytest.approx(0.230456, rel=1e-5)
    assert c["d_diff_mm"] == pytest.approx(0.0417819, rel=1e-5)
    assert c["d_mm"] == pytest.approx(np.hypot(0.230456, 0.0417819), rel=1e-5)
    assert c["d_mm"] / cam.pitch_mm == pytest.approx(11.71, abs=0.01)


def test_aperture_points_cover_the_disc_and_one_ray_is_the_pinhole():
    np.testing.assert_array_equal(aperture_points(1, 3.0), np.zeros((1, 2)))
    p = aperture_points(60, 3.0)
    assert np.linalg.norm(p, axis=1).max() <= 1.5 and np.linalg.norm(p, axis=1).max() > 1.35
    np.testing.assert_allclose(p.mean(0), 0, atol=0.05)
    with pytest.raises(ValueError, match="at least one ray"):
        aperture_points(0, 3.0)


def test_aperture_rays_meet_on_the_background_point_of_their_pixel():
    cam = arc_rig(binning=40)[2]
    d = cam.pixel_directions()[::50]
    o, r = aperture_rays(cam, d, 12)
    focus = torch.as_tensor(cam.position) + d * (cam.background_mm / (d @ torch.as_tensor(cam.rotation[:, 2])))[:, None]
    t = ((focus[:, None] - o) * r).sum(-1, keepdim=True)
    torch.testing.assert_close(o + t * r, focus[:, None].expand_as(o), atol=1e-9, rtol=0)


def test_pinhole_limits_give_the_ideal_deflections():
    ph = PHANTOMS.build({"name": "gaussian_blob", "shape": [20, 20, 20], "voxel_mm": 2.0, "width_mm": 6.0})
    delta = torch.as_tensor(ph.delta, dtype=torch.float64)
    cam = arc_rig(binning=40)[0]
    d = cam.pixel_directions()
    ideal = voxel_deflection(delta, ph.box, torch.as_tensor(cam.position).expand_as(d), d)
    torch.testing.assert_close(aperture_deflection(delta, ph.box, cam, d, 1), ideal, atol=1e-15, rtol=0)
    from dataclasses import replace
    pinhole = replace(cam, f_number=1e12)  # 60 rays through a vanishing aperture
    torch.testing.assert_close(aperture_deflection(delta, ph.box, pinhole, d, 60), ideal, atol=1e-12, rtol=1e-6)
    blurred = aperture_deflection(delta, ph.box, replace(cam, f_number=4.0), d, 60)
    assert blurred.abs().max() < 0.95 * ideal.abs().max()  # a wide aperture smears the peak deflection
