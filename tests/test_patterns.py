import numpy as np
import pytest
from scipy.spatial import cKDTree

from nerif.sensing.patterns import PATTERNS, poisson_disk_points


@pytest.mark.parametrize("name", ["poisson_disk", "random_dots", "wavelet_noise"])
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
