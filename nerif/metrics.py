"""Error metrics of a reconstruction (temperatures in K, deflections in rad)."""
from __future__ import annotations

import numpy as np
import torch


def rmse(a, b, where=None) -> float:
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if where is not None:
        d = d[where]
    return float(np.sqrt(np.mean(d**2))) if d.size else float("nan")


def flame_region(T_true: np.ndarray, T0: float, threshold_K: float = 1.0) -> np.ndarray:
    """Voxels where the true field differs from ambient by more than ``threshold_K``."""
    return np.abs(T_true - T0) > threshold_K


def deflection_rmse(eps: torch.Tensor, eps_obs: torch.Tensor) -> float:
    """sqrt(mean over rays of |eps - eps_obs|^2); (R, 3) each."""
    return float(((eps - eps_obs) ** 2).sum(-1).mean().sqrt())
