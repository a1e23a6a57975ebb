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


def value_range(x: torch.Tensor) -> float:
    """max - min over all components: the peak of :func:`psnr_db`."""
    return float(x.max() - x.min())


def psnr_db(pred: torch.Tensor, obs: torch.Tensor, peak: float | None = None) -> float:
    """Peak signal-to-noise ratio of (R, C) predictions against observations: 10 log10(peak^2 / MSE), MSE the
    mean over rays and components, ``peak`` the observations' :func:`value_range` unless given (give the range of
    every observation when scoring a subset, so that subsets are comparable). NaN where the observations span no
    range (undefined, not -inf)."""
    obs = obs.double()
    mse = float(((pred.double() - obs) ** 2).mean())
    peak = value_range(obs) if peak is None else peak
    if not peak > 0:  # observations all equal (a view that sees no deflection): no peak to compare with
        return float("nan")
    return float("inf") if mse == 0 else 10.0 * float(np.log10(peak**2 / mse))


def select_by_heldout(runs: dict) -> object:
    """The key of the run (key -> its metrics) that predicts the held-out rays best: the lowest
    ``heldout_deflection_rmse``. A choice made from the data alone, never from errors against a truth, so that it
    is the choice a user without the truth would make (a regularisation weight, a stopping point)."""
    scored = {k: m["heldout_deflection_rmse"] for k, m in runs.items() if m.get("heldout_deflection_rmse") is not None}
    if not scored:
        raise ValueError("no run has held-out rays to choose by (hold out views: data.heldout_split or "
                         "data.heldout_views)")
    return min(scored, key=scored.get)
