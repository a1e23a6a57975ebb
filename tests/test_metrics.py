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
