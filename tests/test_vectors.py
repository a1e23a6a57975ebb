"""The normalised median test (:mod:`nerif.sensing.vectors`)."""
import numpy as np
import pytest

from nerif.sensing.vectors import median_test


def test_an_outlier_patch_is_rejected_and_a_smooth_field_with_noise_is_not():
    rng = np.random.default_rng(0)
    r, c = np.mgrid[0:40, 0:50].astype(float)
    u = np.stack([0.5 * np.sin(c / 8), 0.3 * np.cos(r / 6)], -1) + rng.normal(0, 0.02, (40, 50, 2))
    valid = np.ones((40, 50), bool)
    assert median_test(u, valid).sum() == 0  # the flow's noise (0.02 px) is under the floor
    bad = u.copy()
    bad[20, 30] += (1.5, -1.0)  # single wild vectors, as at the burner's edge or on dust
    bad[5, 7] += (0.0, 0.8)
    bad[30:32, 10:12] += (-0.9, 0.6)  # a patch of 2 x 2: each outlier's neighbours are still mostly good
    rejected = median_test(bad, valid)
    assert rejected[20, 30] and rejected[5, 7] and rejected[30:32, 10:12].all() and rejected.sum() == 6
    valid[20, 29] = False  # an invalid neighbour does not vote, and is never rejected itself
    assert median_test(bad, valid)[20, 30] and not median_test(bad, valid)[20, 29]


def test_the_floor_follows_the_views_own_noise():
    """Issue 49: a camera whose flow scatters 0.3 px where nothing flows lost 3 % of its vectors to a floor of 0.1 px;
    the floor is at least twice the vectors' measured noise, and the test still finds a wild vector there."""
    from nerif.sensing.vectors import vector_noise

    rng = np.random.default_rng(1)
    u = rng.normal(0, 0.3, (60, 80, 2))
    valid = np.ones((60, 80), bool)
    assert vector_noise(u, valid) == pytest.approx(0.3 * 1.2, rel=0.25)  # the scatter about the neighbours' median
    assert median_test(u, valid).mean() < 0.002
    u[30, 40] += (4.0, -3.0)
    assert median_test(u, valid)[30, 40]


def test_a_coherent_sharp_structure_is_kept_and_a_lone_outlier_is_not():
    """A shock or a flame sheet moves a line of vectors together, one ray wide: each differs from its neighbours'
    median as an outlier does, but four or more around it share its value."""
    r, c = np.mgrid[0:40, 0:50].astype(float)
    u = np.stack([0.1 * np.sin(c / 9), 0.1 * np.cos(r / 7)], -1)
    valid = np.ones((40, 50), bool)
    u[5:35, 20] += (1.5, 0.0)  # a sheet across the view
    u[12, 40] += (1.5, 0.0)  # one wild vector
    rejected = median_test(u, valid)
    assert not rejected[6:34, 20].any() and rejected[12, 40]  # the line's last vectors have fewer alike
