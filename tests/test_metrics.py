import warnings

import numpy as np
import pytest
import torch

from nerif.metrics import deflection_rmse, flame_region, rmse


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
