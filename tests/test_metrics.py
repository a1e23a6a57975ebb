import warnings

import numpy as np
import pytest
import torch

from nerif.metrics import deflection_rmse, flame_region, rmse, temperature_std
from nerif.physics import Ambient

AMB = Ambient(T0=300.0, n0=1.00027, T_max=2000.0)


def test_rmse_and_flame_region():
    truth = np.array([296.15, 296.15, 1000.0, 1500.0])
    rec = np.array([300.15, 292.15, 1100.0, 1500.0])
    assert rmse(rec, truth) == pytest.approx(np.sqrt((16 + 16 + 10000) / 4))
    flame = flame_region(truth, 296.15)
    assert flame.tolist() == [False, False, True, True]
    assert rmse(rec, truth, flame) == pytest.approx(np.sqrt(10000 / 2))


def test_deflection_rmse_is_over_vector_norms():
    eps = torch.tensor([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]])
    assert deflection_rmse(eps, torch.zeros(2, 3)) == pytest.approx(np.sqrt(25 / 2))


def test_psnr_against_the_observed_range():
    from nerif.metrics import psnr_db

    obs = torch.linspace(0.0, 2.0, 300).reshape(100, 3)
    # error 0.02 everywhere, peak-to-peak 2: 10 log10(4 / 4e-4) = 40 dB
    assert psnr_db(obs + 0.02, obs) == pytest.approx(40.0, abs=1e-4)
    assert psnr_db(obs, obs) == float("inf")
    zero = torch.zeros_like(obs)  # issue 28: a view without deflections printed "PSNR -inf dB" and a numpy warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isnan(psnr_db(obs, zero))


def test_temperature_figures_give_the_peak_where_it_is_and_the_volume_above_a_temperature():
    from nerif.geometry import ProbeBox
    from nerif.metrics import temperature_figures

    box = ProbeBox((10, 20, 10), 2.0)  # voxels of 8 mm3
    T = np.full(box.shape, 300.0)
    T[4:7, 10:15, 4:7] = 1200.0  # 45 voxels above 1000 K: 0.36 cm3
    T[5, 12, 6] = 1800.0
    truth = T.copy()
    truth[5, 12, 6] = 1900.0
    truth[4:7, 15, 4:7] = 1100.0  # 9 voxels more
    f = temperature_figures(T, box.axes(), 1000.0, truth)
    assert f["T_peak_K"] == 1800.0 and f["T_peak_position_mm"] == [1.0, 5.0, 3.0]
    assert abs(f["flame_volume_cm3"] - 45 * 8e-3) < 1e-12 and abs(f["flame_volume_true_cm3"] - 54 * 8e-3) < 1e-12
    assert f["T_peak_true_K"] == 1900.0 and f["T_peak_error_K"] == -100.0 and f["flame_volume_above_K"] == 1000.0
    assert "T_peak_true_K" not in temperature_figures(T, box.axes(), 1000.0)


def _blob_temperature():
    """A smooth, flat-topped hot blob on a 2 mm grid (sigma of air at 300 K and a flame to 1800 K), and sigma -> T."""
    from nerif.geometry import ProbeBox
    from nerif.physics import Ambient

    amb = Ambient(T0=300.0, n0=1.000293, T_max=2000.0)
    box = ProbeBox((16, 24, 16), 2.0)
    x, y, z = np.meshgrid(*box.axes(), indexing="ij")
    T = 300.0 + 1500.0 * np.exp(-((x**2 + (y - 4.0) ** 2 + z**2) / 10.0**2) ** 2)  # flat-topped: no finer peak
    return box, amb, amb.sigma_from_temperature(T), amb.temperature_from_sigma


def test_the_intervals_of_the_peak_and_the_volume_hold_the_truth_as_often_as_they_say():
    """Issue 59: a reconstruction wrong by one offset over the whole field (an error correlated over the flame, one
    draw of N(0, u) per reconstruction) with sigma_std = u: the peak's and the volume's 2-sigma intervals hold the
    true figures in about 95 % of the draws (both bounds are monotonic in the offset: exactly when |offset| <= 2u
    on the cold side, the hot side wider); a standard deviation a third too small holds them far less often."""
    from nerif.metrics import reported_intervals, temperature_figures, within_intervals

    box, amb, truth, temperature = _blob_temperature()
    rng = np.random.default_rng(0)
    u = 0.03
    held = {0.0: [], 1.0: []}
    for _ in range(300):
        offset = rng.normal(0.0, u)
        sigma = truth + offset
        fig = temperature_figures(temperature(sigma), box.axes(), 1000.0, temperature(truth))
        for shrink in held:
            std = np.full(sigma.shape, u / (3.0 if shrink else 1.0))
            iv = reported_intervals(sigma, std, temperature, box.axes(), 1000.0, amb.sigma_from_temperature(2000.0))
            held[shrink].append(within_intervals({**fig, **iv}))
    for key in ("T_peak_in_interval", "flame_volume_in_interval", "T_peak_position_in_interval"):
        share = np.mean([w[key] for w in held[0.0]])
        assert 0.93 <= share <= 1.0, (key, share)
    assert np.mean([w["T_peak_in_interval"] for w in held[1.0]]) < 0.75
    assert np.mean([w["flame_volume_in_interval"] for w in held[1.0]]) < 0.9  # a count of voxels: steps


def test_the_peak_interval_of_a_flat_top_is_the_band_of_its_value_and_a_lone_spike_widens_it():
    """A plateau of sigma s0 over a box of voxels, domed by 1e-4 towards its centre (nothing finer than a voxel),
    with sigma_std u: the peak's interval is [T(s0 + 2u), T(s0 - 2u)], the peak could lie anywhere on the plateau
    (the box of its voxels, half a voxel out), and the volume interval counts the plateau alone. A one-voxel spike above it
    (what a field cannot resolve: a sharp tip smoothed, or streaks crossing) moves both bounds further than 2u."""
    from nerif.geometry import ProbeBox
    from nerif.metrics import reported_intervals
    from nerif.physics import Ambient

    amb = Ambient(T0=300.0, n0=1.000293, T_max=2000.0)
    T_of = amb.temperature_from_sigma
    box = ProbeBox((16, 16, 16), 2.0)
    s0, u = float(amb.sigma_from_temperature(1500.0)), 0.02
    x, y, z = np.meshgrid(*[np.arange(n) - c for n, c in zip(box.shape, (7.5, 7.5, 7.5))], indexing="ij")
    sigma = np.zeros(box.shape)
    sigma[2:14, 2:14, 2:14] = s0 * (1.0 + 1e-4 * np.exp(-(x**2 + y**2 + z**2) / 18.0))[2:14, 2:14, 2:14]  # 1728
    std = np.full(box.shape, u)
    iv = reported_intervals(sigma, std, T_of, box.axes(), 1000.0, -1.05)
    top = sigma.min()  # the dome's centre
    # the dome's curvature (1e-4 of its depth) moves the hot bound by its read-through-the-resolution part alone
    assert iv["T_peak_interval_K"] == pytest.approx([T_of(top + 2 * u), T_of(top - 2 * u)], rel=1e-4)
    axes = box.axes()
    np.testing.assert_allclose(iv["T_peak_position_interval_mm"], [[axes[k][2] - 1, axes[k][13] + 1] for k in range(3)])
    assert iv["flame_volume_interval_cm3"] == pytest.approx([1728 * 8e-3, 1728 * 8e-3])
    spike, narrow = sigma.copy(), np.full(box.shape, 0.005)
    spike[7, 7, 7] = float(amb.sigma_from_temperature(1900.0))
    sp = reported_intervals(spike, narrow, T_of, box.axes(), 1000.0, -1.05)
    assert sp["T_peak_interval_K"][0] < T_of(spike[7, 7, 7] + 2 * 0.005) - 50.0
    assert sp["T_peak_interval_K"][1] > T_of(spike[7, 7, 7] - 2 * 0.005) + 50.0
    for (lo, hi), a in zip(sp["T_peak_position_interval_mm"], axes):  # the spike or anywhere on the plateau
        assert lo <= a[7] <= hi
    clipped = reported_intervals(sigma, np.full(box.shape, 1.0), T_of, box.axes(), 1000.0, -1.05)
    assert clipped["T_peak_interval_K"][1] == pytest.approx(T_of(-1.05))  # no hotter than the prior allows


def test_a_blurred_cores_peak_read_through_the_resolution_is_closer_and_its_interval_holds_the_truth():
    """Issue 66: a Gaussian core (3 voxels) at 1850 K blurred by the run's resolution (0.8 voxel) reads cold in the
    field (1222 K: at 1850 K a 1 % error of sigma is 5 % of T); read back through that resolution
    (:func:`resolved_peak_figures`) it keeps under a quarter of that error (the first order's rest), and the interval
    about it holds the truth."""
    from scipy.ndimage import gaussian_filter

    from nerif.geometry import ProbeBox
    from nerif.metrics import reported_intervals, resolved_peak_figures
    from nerif.physics import Ambient
    from nerif.resolution import resolved_peak

    amb = Ambient(T0=296.15, n0=1.00027, T_max=2000.0)
    box = ProbeBox((31, 31, 31), 1.0)
    g = np.meshgrid(*[np.arange(31) - 15] * 3, indexing="ij")
    truth = float(amb.sigma_from_temperature(1850.0)) * np.exp(-sum(x**2 for x in g) / (2 * 3.0**2))
    field = gaussian_filter(truth, 0.8, mode="nearest")
    f = resolved_peak_figures(resolved_peak(field, 0.8, 1.0, -1.05), amb.temperature_from_sigma, 1850.0)
    assert f["T_peak_field_K"] < 0.8 * 1850.0 and abs(f["T_peak_K"] - 1850.0) < 0.25 * (1850.0 - f["T_peak_field_K"])
    assert f["T_peak_resolution_K"] == pytest.approx(f["T_peak_K"] - f["T_peak_field_K"]) and f["T_peak_resolved"] == 1
    assert f["T_peak_error_K"] == pytest.approx(f["T_peak_K"] - 1850.0)
    iv = reported_intervals(field, np.full(box.shape, 0.005), amb.temperature_from_sigma, box.axes(), 1000.0, -1.05,
                            blur_vox=0.8)
    assert iv["T_peak_interval_K"][0] < 1850.0 < iv["T_peak_interval_K"][1]
    about = reported_intervals(field, np.full(box.shape, 0.005), amb.temperature_from_sigma, box.axes(), 1000.0,
                               -1.05, blur_vox=0.8, peak=resolved_peak(field, 0.8, 1.0, -1.05))
    lo, hi = about["T_peak_interval_K"]
    assert lo < 1850.0 < hi and lo > iv["T_peak_interval_K"][0] and hi < iv["T_peak_interval_K"][1]


@pytest.mark.parametrize("width_vox", [3.0, 4.0, 6.0])
def test_a_resolved_peaks_interval_holds_the_truth_as_often_as_it_says_and_no_more(width_vox):
    """Issue 66: a Gaussian core at 1850 K blurred by the run's resolution (0.8 voxel) and wrong by one offset
    N(0, u) over the whole field, read through that resolution: the interval about the corrected peak (z u
    hotter, the correction's rest too, and z sqrt(u^2 + b^2) colder) holds the truth in at least 92 % of the draws,
    with a standard deviation a third too small less often, and is narrower than the interval that counts the
    correction as an uncertainty both ways and as a move."""
    from scipy.ndimage import gaussian_filter

    from nerif.geometry import ProbeBox
    from nerif.metrics import reported_intervals
    from nerif.physics import Ambient
    from nerif.resolution import resolved_peak

    amb = Ambient(T0=296.15, n0=1.00027, T_max=2000.0)
    T_of = amb.temperature_from_sigma
    box = ProbeBox((25, 25, 25), 1.0)
    g = np.meshgrid(*[np.arange(25) - 12] * 3, indexing="ij")
    truth = float(amb.sigma_from_temperature(1850.0)) * np.exp(-sum(x**2 for x in g) / (2 * width_vox**2))
    blurred = gaussian_filter(truth, 0.8, mode="nearest")
    rng, u = np.random.default_rng(1), 0.006
    held, narrow, wider = {1.0: [], 3.0: []}, [], []
    for _ in range(200):
        field = blurred + rng.normal(0.0, u)
        peak = resolved_peak(field, 0.8, 1.0, -1.05)
        assert peak.resolved
        for shrink in held:
            lo, hi = reported_intervals(field, np.full(box.shape, u / shrink), T_of, box.axes(), 1000.0, -1.05,
                                        blur_vox=0.8, peak=peak)["T_peak_interval_K"]
            held[shrink].append(lo <= 1850.0 <= hi)
            if shrink == 1.0:
                whole = reported_intervals(field, np.full(box.shape, u), T_of, box.axes(), 1000.0, -1.05,
                                           blur_vox=0.8)["T_peak_interval_K"]
                narrow.append(hi - lo)
                wider.append(whole[1] - whole[0])
    assert 0.92 <= np.mean(held[1.0]) <= 1.0, np.mean(held[1.0])
    assert np.mean(held[3.0]) < np.mean(held[1.0])  # on its cold side the correction's size dominates: less so
    assert np.median(narrow) < 0.8 * np.median(wider)


def test_a_fields_flame_is_where_its_magnitude_passes_a_share_of_its_peak():
    from nerif.metrics import flame_share_region

    sigma = np.array([0.0, -0.01, -0.06, -1.0, 0.2])
    assert flame_share_region(sigma).tolist() == [False, False, True, True, True]
    assert flame_share_region(sigma, 0.5).tolist() == [False, False, False, True, False]
    assert not flame_share_region(np.zeros(3)).any() and flame_share_region(np.zeros(3), empty=True).all()


def test_a_temperatures_standard_deviation_is_sigmas_times_the_slope_of_t():
    """Air, sigma = -1 at T_max: T = T0 / (1 + k sigma), k = 1 - T0 / T_max, so |dT/dsigma| = T0 k / (1 + k sigma)^2."""
    sigma, std = np.array([-0.9, -0.5, 0.0]), np.array([0.01, 0.02, 0.03])
    k = 1 - AMB.T0 / AMB.T_max
    slope = AMB.T0 * k / (1 + k * sigma) ** 2
    np.testing.assert_allclose(AMB.temperature_from_sigma(sigma), AMB.T0 / (1 + k * sigma), rtol=1e-6)
    np.testing.assert_allclose(temperature_std(AMB, sigma, std), slope * std, rtol=1e-6)


def test_the_peaks_interval_reads_the_spread_of_the_peaks_own_voxel_where_several_reach_the_prior():
    """Two voxels beyond the prior's bound read alike in T (both clipped there); the interval about the resolved peak
    takes the standard deviation of the hottest in sigma, the voxel the peak was read at."""
    from nerif.geometry import ProbeBox
    from nerif.metrics import reported_intervals
    from nerif.physics import Ambient
    from nerif.resolution import resolved_peak

    amb = Ambient(T0=300.0, n0=1.000293, T_max=2000.0)
    box = ProbeBox((9, 9, 9), 1.0)
    sigma = np.full(box.shape, -0.5)
    sigma[2, 4, 4], sigma[6, 4, 4] = -1.1, -1.3  # the first in memory order is not the hottest
    std = np.full(box.shape, 0.2)
    std[6, 4, 4] = 0.001
    peak = resolved_peak(sigma, 0.0, 1.0, -1.05)
    assert peak.index == (6, 4, 4)
    lo, hi = reported_intervals(sigma, std, amb.temperature_from_sigma, box.axes(), 1000.0, -1.05, blur_vox=0.0,
                                peak=peak)["T_peak_interval_K"]
    assert lo == pytest.approx(float(amb.temperature_from_sigma(np.float64(-1.05 + 2 * 0.001))))
