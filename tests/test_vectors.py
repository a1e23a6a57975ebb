"""The normalised median test (:mod:`nerif.sensing.vectors`)."""
import numpy as np

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
