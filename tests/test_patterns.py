import numpy as np
import pytest
from scipy.spatial import cKDTree

from nerif.sensing.patterns import PATTERNS, poisson_disk_points


@pytest.mark.parametrize("name", ["poisson_disk", "random_dots", "wavelet_noise", "dot_grid"])
def test_patterns_are_seeded_images_in_unit_range(name):
    a = PATTERNS.build({"name": name}, height=96, width=128, seed=3)
    b = PATTERNS.build({"name": name}, height=96, width=128, seed=3)
    c = PATTERNS.build({"name": name}, height=96, width=128, seed=4)
    assert a.shape == (96, 128) and a.dtype == np.float32
    assert a.min() >= 0 and a.max() <= 1 and a.std() > 0.15  # contrast for the optical flow
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.05


def test_poisson_disk_points_keep_their_distance_and_fill_the_image():
    p = poisson_disk_points(200, 300, 5.0, np.random.default_rng(0))
    d, _ = cKDTree(p).query(p, k=2)
    assert d[:, 1].min() >= 5.0 - 1e-9
    assert d[:, 1].mean() < 1.25 * 5.0  # maximal: no room left for another point nearly anywhere
    assert p[:, 0].min() >= 0 and p[:, 0].max() < 200 and p[:, 1].max() < 300


@pytest.mark.parametrize("name", ["poisson_disk", "random_dots", "wavelet_noise", "dot_grid"])
def test_a_pattern_sampled_finer_is_the_same_background(name):
    """``samples`` s: the same draw on a grid s times finer, whose pixel means give back the pixel-sampled
    pattern (to the anti-aliasing's and the band's resampling differences, far below the pattern's contrast)."""
    a = PATTERNS.build({"name": name}, height=48, width=64, seed=3)
    f = PATTERNS.build({"name": name}, height=48, width=64, seed=3, samples=4)
    assert f.shape == (192, 256) and f.dtype == np.float32 and f.min() >= 0 and f.max() <= 1
    means = f.reshape(48, 4, 64, 4).mean((1, 3))
    assert np.abs(means - a).mean() < 0.1 * a.std()
    assert np.abs(f.reshape(48, 4, 64, 4) - means[:, None, :, None]).mean() > 0.02  # detail within a pixel


def test_a_dot_grid_covers_its_share_and_repeats_at_its_pitch():
    """A regular grid: each period holds one dot, pi r^2 / pitch^2 of the area (to the rasterised edge, 1/8 px
    wide), and the image shifted by one pitch
    is the image."""
    g = PATTERNS.build({"name": "dot_grid", "pitch_px": 12.0, "radius_px": 3.0}, height=96, width=120, seed=2)
    assert g.mean() == pytest.approx(np.pi * 9 / 144, rel=0.1)
    np.testing.assert_allclose(g[12:, :], g[:-12, :], atol=0.02)
    np.testing.assert_allclose(g[:, 12:], g[:, :-12], atol=0.02)
