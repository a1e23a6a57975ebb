"""The measurement stage of one view (:func:`nerif.sensing.measurement.measure_view`): a known displacement comes
out on the ray grid in pixels of the full sensor; a pixel without a usable estimate, or outside the region, is
invalid and carries no value."""
import numpy as np
import pytest
import torch

from nerif.sensing.flow import FLOW
from nerif.sensing.imaging import diffraction_blur, warp
from nerif.sensing.measurement import measure_view
from nerif.sensing.patterns import PATTERNS


def pair(shift_px, H=160, W=200):
    background = torch.as_tensor(PATTERNS.build({"name": "poisson_disk"}, height=H, width=W, seed=2))
    u = torch.zeros(H, W, 2)
    u[..., 0], u[..., 1] = shift_px
    return (diffraction_blur(warp(background, u), 2.1).numpy(), diffraction_blur(background, 2.1).numpy())


def test_a_uniform_shift_comes_out_in_full_sensor_pixels_on_the_ray_grid():
    """Images shifted (0.6, -0.3) of their pixels: the ray grid (4 x 4 image pixels a ray) holds that shift, every
    pixel valid; the same images taken as 2 x 2-binned (each image pixel two sensor pixels across) hold twice it."""
    distorted, reference = pair((0.6, -0.3))
    m1, m2 = (measure_view(distorted, reference, {"name": "farneback"}, (40, 50), image_binning=b) for b in (1, 2))
    assert m1.displacement.shape == (40, 50, 2) and m1.valid.all()
    inner = m1.displacement[4:-4, 4:-4].reshape(-1, 2)
    np.testing.assert_allclose(np.median(inner, 0), [0.6, -0.3], atol=0.05)  # Farneback's bias: 0.036 px
    np.testing.assert_allclose(m2.displacement, 2 * m1.displacement, rtol=1e-6)
    assert m1.found["valid_fraction"] == 1.0 and m1.found["displacement_max_px"] > 0.5


def test_pixels_without_an_estimate_or_outside_the_region_are_invalid_and_carry_nothing(monkeypatch):
    """A flow with a patch of NaN (an estimator's rejected vectors) and a region that leaves out the left columns:
    those pixels are invalid, NaN, and out of the figures; the others keep the flow's values."""
    distorted, reference = pair((0.5, 0.0))
    build = FLOW.build

    def flow_with_a_hole(cfg, **images):
        u = build(cfg, **images)
        u[40:80, 100:140] = np.nan
        return u

    monkeypatch.setattr(FLOW, "build", flow_with_a_hole)
    region = np.ones((40, 50), bool)
    region[:, :5] = False
    m = measure_view(distorted, reference, {"name": "farneback"}, (40, 50), region=region)
    hole = np.zeros((40, 50), bool)
    hole[10:20, 25:35] = True  # the image's [40, 80) x [100, 140) in blocks of 4
    np.testing.assert_array_equal(m.valid, region & ~hole)
    assert np.isnan(m.displacement[~m.valid]).all() and np.isfinite(m.displacement[m.valid]).all()
    assert m.found["valid_fraction"] == pytest.approx(m.valid.mean())
