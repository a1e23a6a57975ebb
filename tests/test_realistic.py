"""Realistic sensing: seeded, recording what it saw, measuring the perpendicular part through a noisy flow."""
import numpy as np
import torch

from nerif.data import DATASETS
from nerif.renderers import perpendicular


BLOB = {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0, "width_mm": 5.0}
REALISTIC = {"name": "synthetic", "render_supersample": 1, "phantom": BLOB, "rig": {"name": "arc", "n_cameras": 2, "binning": 40},
             "T_max": 2000.0, "sensing": "realistic",
             "sensor": {"aperture_rays": 8, "noise_variance": 1e-4, "image_binning": 8, "seed": 0,
                        "pattern": {"name": "poisson_disk"}, "flow": {"name": "farneback"}}}


def test_realistic_sensing_is_seeded_and_records_what_it_saw():
    a = DATASETS.build(REALISTIC)
    b = DATASETS.build(REALISTIC)
    c = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], seed=1)))
    torch.testing.assert_close(a.eps, b.eps)
    assert not torch.equal(a.eps, c.eps)
    rec = a.sensing  # the chain's truth; what it measured is in the views, as a capture's
    assert tuple(a.images[0].reference.shape) == (160, 90) and len(a.images) == 2
    assert rec.u_true.shape == (2, 32, 18, 2) and a.views[0].measured_px.shape == (32, 18, 2)
    assert 0 < float(rec.displacement_rmse_px) < 0.1
    # the observed deflections are the measurable part of the ideal ones, seen through a blurred, noisy flow
    # estimate: close, not equal; and perpendicular to their rays, which the scene declares
    ideal = DATASETS.build(dict(REALISTIC, sensing="ideal"))
    assert a.perpendicular_only and not ideal.perpendicular_only
    # the rays both keep (the measurement stage may reject a vector or two), view by view
    both = torch.cat([torch.isin(ideal.pixel[ideal.view_slice(v)], a.pixel[a.view_slice(v)]) for v in range(2)])
    assert int(both.sum()) == len(a.eps) >= len(ideal.eps) - 2
    target = perpendicular(ideal.eps, ideal.dirs)[both]
    assert torch.isfinite(a.eps).all() and 0 < float((a.eps - target).norm() / target.norm()) < 0.5
    assert float((a.eps * a.dirs).sum(-1).abs().max()) < 1e-6 * float(a.eps.norm(dim=-1).max())


def test_the_flames_light_and_a_gain_drift_change_only_the_distorted_image_as_set():
    """Luminosity: light added to the distorted exposure, brightest (the given fraction of the background's mean)
    where the flame's projection is largest and none outside it; gain drift: that exposure scaled. The reference
    image and the deflections' geometry stay; the scene carries both images for the image data term."""
    quiet = dict(REALISTIC["sensor"], noise_variance=0.0)
    plain = DATASETS.build(dict(REALISTIC, sensor=quiet))
    lit = DATASETS.build(dict(REALISTIC, sensor=dict(quiet, luminosity=0.3)))
    drift = DATASETS.build(dict(REALISTIC, sensor=dict(quiet, gain_drift=0.1)))
    for s in (lit, drift):
        torch.testing.assert_close(s.images[0].reference, plain.images[0].reference, rtol=0, atol=0)
    ref = plain.images[0].reference.double()
    glow = (lit.images[0].distorted - plain.images[0].distorted).double()
    assert abs(float(glow.max()) - 0.3 * float(ref.mean())) < 2.5 / 255  # 8-bit images
    assert float(glow[:, :5].abs().max()) <= 1.0 / 255  # the image's edge columns see no flame
    unclipped = drift.images[0].distorted < 250 / 255  # 8-bit: brighter pixels saturate
    ratio = drift.images[0].distorted[unclipped].double().sum() / plain.images[0].distorted[unclipped].double().sum()
    assert abs(float(ratio) - 1.1) < 0.01
    assert plain.images[0].reference.shape == (160, 90) and plain.images[0].camera.binning == 8



def calibrated_scene(cache_dir, *overrides):
    """A blob seen by 3 hand-placed cameras (``rig=calibrated``: each at its own distance, with its own lens)."""
    from nerif.configs import compose, group

    cfg = compose(["data.sensing=realistic", "rig=calibrated", "rig.n_cameras=3", "rig.binning=8",
                   "phantom=gaussian_blob", "phantom.shape=[16,16,16]", "phantom.voxel_mm=3.0", "phantom.width_mm=7.0",
                   "data.sensor.aperture_rays=4", "data.render_supersample=1", f"data.cache_dir={cache_dir}",
                   *overrides])
    return DATASETS.build(group(cfg, "data"), device="cpu")


def test_the_aperture_cache_renders_again_for_another_lens_distortion(tmp_path):
    """Issue 36: the aperture renderings were keyed on pose, lens and sensor but not on the principal point, aspect
    or distortion: a second run with another ``rig.k1`` reused the first run's renderings."""
    def build(k1: float):
        return calibrated_scene(tmp_path, f"rig.k1=[{k1},{k1}]")

    build(-0.2)
    assert len(list(tmp_path.glob("aperture-*.npz"))) == 3
    build(0.05)
    assert len(list(tmp_path.glob("aperture-*.npz"))) == 6  # every camera rendered again


def test_the_circle_of_confusion_is_each_views_own(tmp_path):
    """Issue 36: ``circle_of_confusion_px`` was the last view's. Cameras at different distances from the probe blur
    it differently: the record holds one value per view, each the optics' own for that camera."""
    from nerif.sensing.optics import circle_of_confusion

    scene = calibrated_scene("null")
    coc = scene.sensing.circle_of_confusion_px
    own = [circle_of_confusion(c.full_sensor)["d_mm"] / (c.pitch_mm / c.binning) for c in scene.cameras]
    assert coc.shape == (3,) and np.ptp(coc) > 0.01 * coc.max()
    np.testing.assert_allclose(coc, own, rtol=1e-9)


def test_an_opaque_burner_is_dark_in_both_exposures_found_occluded_and_left_unknown():
    """Issue 37: ``burner_radius_mm``: the tube's pixels (:func:`nerif.sensing.burner.burner_pixels`, tested on their
    own in ``test_burner.py``) are dark and without texture in both exposures; the measurement stage finds them
    occluded, and they carry no ray."""
    from nerif.sensing.burner import DARK, burner_pixels
    from nerif.geometry import RIGS

    scene = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], burner_radius_mm=6.0)))
    tube = burner_pixels(RIGS.build(REALISTIC["rig"])[0].unbinned(40).binned(8), 6.0, -16.0)  # the images' grid
    for images in (255 * scene.images[0].reference.numpy(), 255 * scene.images[0].distorted.numpy()):
        assert abs(float(np.median(images[tube])) - 255 * DARK) < 3  # dark
        assert float(images[tube].std()) < 5 < 30 < float(images[~tube].std())  # and without the pattern's texture
    found, true = np.array([f.occluded for f in scene.findings]), scene.sensing.occluded_true
    assert np.all(found >= 0.9 * true) and np.all(found < true + 0.1), (found, true)
    hidden = (torch.nn.functional.avg_pool2d(torch.as_tensor(tube, dtype=torch.float32)[None], 5)[0] > 0).numpy()
    ideal = DATASETS.build(dict(REALISTIC, sensing="ideal"))
    crossing = np.zeros(hidden.size, bool)  # the blocks whose ray crosses the probe box
    crossing[ideal.pixel[ideal.view_slice(0)].numpy()] = True
    crossing = crossing.reshape(hidden.shape)
    assert (hidden & crossing).any() and not scene.valid_images[0][hidden & crossing].any()  # unknown: no carving


def test_light_brighter_than_full_scale_clips_and_the_stage_counts_it():
    """The flame's light (its blur is tested in ``test_emission.py``) brighter than the sensor's full scale
    clips the distorted image. Where the pattern's dark dots still show through, the texture is there: counted as
    clipped, not left out (issue 49); where the light clips them too, the stage leaves those pixels out."""
    bright = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], luminosity=20.0)))
    assert (bright.images[0].distorted == 1.0).any() and all(f.clipped > 0.04 for f in bright.findings)
    assert all(f.saturated < 0.5 * f.clipped for f in bright.findings)
    blinding = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], luminosity=200.0)))
    assert all(f.saturated > 0.05 for f in blinding.findings)


def test_pixels_that_integrate_the_background_measure_as_well_and_a_bad_count_is_refused():
    """``pixel_samples``: the camera's pixels integrate the displaced background (4 x 4 points) or read the
    pattern at their displaced centres (1): another image pair, measured as well, the same rays."""
    integrated = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], pixel_samples=4)))
    centres = DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], pixel_samples=1)))
    assert not torch.equal(integrated.images[0].distorted, centres.images[0].distorted)
    for s in (integrated, centres):
        assert 0 < float(s.sensing.displacement_rmse_px) < 0.1
    for bad in (0, 2.5):
        try:
            DATASETS.build(dict(REALISTIC, sensor=dict(REALISTIC["sensor"], pixel_samples=bad)))
        except ValueError as e:
            assert "data.sensor.pixel_samples" in str(e)
        else:
            raise AssertionError(f"pixel_samples={bad} was accepted")
