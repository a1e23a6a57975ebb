"""Error metrics of a reconstruction (temperatures in K, deflections in rad)."""
from __future__ import annotations

from typing import Optional

import numpy as np
import torch

from nerif.resolution import ResolvedPeak


def rmse(a, b, where=None) -> float:
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    if where is not None:
        d = d[where]
    return float(np.sqrt(np.mean(d**2))) if d.size else float("nan")


def flame_region(T_true: np.ndarray, T0: float, threshold_K: float = 1.0) -> np.ndarray:
    """Voxels where the true field differs from ambient by more than ``threshold_K``."""
    return np.abs(T_true - T0) > threshold_K


FLAME_SHARE = 0.05  # the flame of a field without a known ambient temperature: |sigma| above this share of its peak


def flame_share_region(sigma: np.ndarray, share: float = FLAME_SHARE, empty: bool = False) -> np.ndarray:
    """(nx, ny, nz) bool: where ``|sigma|`` exceeds ``share`` of its largest value (a field's flame read from the
    field itself); a field of zeros has none (``empty``: what it is then, every voxel or none)."""
    a = np.abs(np.asarray(sigma))
    peak = a.max() if a.size else 0.0
    return a > share * peak if peak > 0 else np.full(a.shape, empty, bool)


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


def uncertainty_scores(sigma: np.ndarray, sigma_std: np.ndarray, sigma_true: np.ndarray,
                       flame_share: float = FLAME_SHARE, core_share: float = 0.05) -> dict:
    """How well a per-voxel standard deviation ``sigma_std`` describes the error of ``sigma`` against
    ``sigma_true`` (all (nx, ny, nz)), over the flame voxels (``|sigma_true|`` above ``flame_share`` of its peak):
    ``coverage_1sigma``, ``coverage_2sigma`` (the share whose error lies within 1 and 2 standard deviations; a
    Gaussian's are 0.683 and 0.954), ``coverage_2sigma_core`` (the same in the hot core: the ``core_share`` of the
    flame voxels of largest ``|sigma_true|``), ``ause`` (the area between the sparsification curves of the RMS error
    when the voxels are removed by ``sigma_std`` and by the error itself, over that of the error alone: 0 for a
    perfect ranking), ``ause_random`` (the same for a random order, the level a ranking must beat),
    ``calibration_error`` (:func:`calibration_error`), ``spearman`` (the rank correlation of ``sigma_std`` and
    ``|error|``). Empty without a flame."""
    from scipy.stats import spearmanr

    truth = np.abs(sigma_true)
    flame = flame_share_region(truth, flame_share)
    if flame.sum() < 10:
        return {}
    err, std = np.abs(sigma - sigma_true)[flame], np.asarray(sigma_std)[flame]
    core = truth[flame] >= np.quantile(truth[flame], 1.0 - core_share)
    return {"coverage_1sigma": float((err <= std).mean()), "coverage_2sigma": float((err <= 2 * std).mean()),
            "coverage_2sigma_core": float((err[core] <= 2 * std[core]).mean()),
            "ause": ause(err, std), "ause_random": ause(err, None), "calibration_error": calibration_error(err, std),
            "spearman": float(spearmanr(std, err)[0])}


CALIBRATION_LEVELS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95)


def calibration_error(err: np.ndarray, std: np.ndarray, levels=CALIBRATION_LEVELS) -> float:
    """The mean over nominal ``levels`` p of ``|observed - p|``, observed the share of ``err`` (M,) within the band of
    +- z_p ``std`` (M,), z_p the Gaussian quantile of a two-sided p: 0 for errors drawn from Gaussians of those
    widths (Lind et al. 2024 recommend it, with AUSE, over rank correlations)."""
    from scipy.stats import norm

    z = norm.ppf((1.0 + np.asarray(levels, dtype=np.float64)) / 2.0)
    observed = (np.abs(err)[None, :] <= z[:, None] * np.asarray(std)[None, :]).mean(1)
    return float(np.abs(observed - np.asarray(levels)).mean())


def ause(err: np.ndarray, std: Optional[np.ndarray], steps: int = 50) -> float:
    """The area under the sparsification error curve (:func:`uncertainty_scores`): RMS of ``err`` (M,) left after
    removing the largest shares of the voxels by ``std`` (M,), less that after removing them by ``err`` itself (the
    oracle), over shares 0 to 0.98, divided by the RMS of all of ``err``. ``std=None``: a random order, whose
    expected curve is the RMS of all of ``err`` at every share."""
    order_err = np.argsort(-err, kind="stable")
    sq = err.astype(np.float64) ** 2
    shares = np.linspace(0.0, 0.98, steps)

    def curve(order):
        if order is None:
            return np.full(len(shares), np.sqrt(sq.mean()))
        rest = np.cumsum(sq[order][::-1])[::-1]  # rest[i]: the sum of squares from rank i on
        return np.array([np.sqrt(rest[int(f * len(sq))] / (len(sq) - int(f * len(sq)))) for f in shares])

    gap = curve(None if std is None else np.argsort(-std, kind="stable")) - curve(order_err)
    return float(((gap[1:] + gap[:-1]) / 2 * np.diff(shares)).sum() / np.sqrt(sq.mean())) if sq.mean() > 0 else 0.0


def voxel_volume_cm3(axes: list) -> float:
    """The volume [cm^3] of one voxel of a grid with voxel centres ``axes`` (x, y, z [mm]; an axis of one voxel
    counts 1 mm)."""
    return float(np.prod([abs(a[1] - a[0]) if len(a) > 1 else 1.0 for a in axes])) / 1000.0


def temperature_std(ambient, sigma: np.ndarray, sigma_std: np.ndarray) -> np.ndarray:
    """The standard deviation of T [K] (nx, ny, nz) of one of sigma, ``sigma_std`` (nx, ny, nz), to first order:
    ``|dT/dsigma| sigma_std`` (``ambient``: :class:`nerif.physics.Ambient`)."""
    h = 1e-4
    slope = (ambient.temperature_from_sigma(sigma + h) - ambient.temperature_from_sigma(sigma - h)) / (2 * h)
    return np.abs(slope) * sigma_std


def temperature_figures(T: np.ndarray, axes: list, hot_K: float, T_true: np.ndarray | None = None) -> dict:
    """What a combustion researcher reports of a temperature field ``T`` (nx, ny, nz) [K] on voxel centres ``axes``
    (x, y, z [mm]): its peak ``T_peak_K`` and where it lies ``T_peak_position_mm`` (x, y, z), and the flame's
    volume ``flame_volume_cm3``, the voxels above ``hot_K`` [K]; where a truth is known, the same of the truth
    (``_true``) and the peak's error ``T_peak_error_K`` (reconstructed less true; negative: too cold)."""
    voxel_cm3 = voxel_volume_cm3(axes)

    def of(field: np.ndarray, suffix: str) -> dict:
        hottest = np.unravel_index(np.argmax(field), field.shape)
        return {f"T_peak{suffix}_K": float(field[hottest]),
                f"T_peak_position{suffix}_mm": [float(a[i]) for a, i in zip(axes, hottest)],
                f"flame_volume{suffix}_cm3": float(np.count_nonzero(field > hot_K)) * voxel_cm3}

    out = {**of(T, ""), "flame_volume_above_K": float(hot_K)}
    if T_true is not None:
        out.update(of(T_true, "_true"))
        out["T_peak_error_K"] = out["T_peak_K"] - out["T_peak_true_K"]
    return out


def resolved_peak_figures(peak, temperature, T_true_peak: Optional[float] = None) -> dict:
    """The peak read through the run's resolution (``peak``: :class:`nerif.resolution.ResolvedPeak`; ``temperature``
    maps sigma to T [K]): ``T_peak_K`` the corrected peak, ``T_peak_field_K`` the field's hottest voxel, what the
    resolution took off it ``T_peak_resolution_K``, ``resolution_mm`` and ``T_peak_resolved`` (1: the core is
    wider than the resolution, 0: about as fine, the field's own peak kept); with ``T_true_peak`` [K] the
    peak's error ``T_peak_error_K`` (reconstructed less true)."""
    field, corrected = float(temperature(np.float64(peak.sigma_field))), float(temperature(np.float64(peak.sigma)))
    out = {"T_peak_K": corrected, "T_peak_field_K": field, "T_peak_resolution_K": corrected - field,
           "resolution_mm": peak.resolution_mm, "T_peak_resolved": float(peak.resolved)}
    if T_true_peak is not None:
        out["T_peak_error_K"] = corrected - float(T_true_peak)
    return out


REMAINDERS = 2.0  # the hot side of a resolved peak's interval: this many times the series' next term (its rest
# is 1.05-1.25 of it for Gaussian cores 3-8 times wider than the resolution; tests/test_metrics.py)


def reported_intervals(sigma: np.ndarray, sigma_std: np.ndarray, temperature, axes: list, hot_K: float,
                       hottest_sigma: float, z: float = 2.0, blur_vox: float = 1.0,
                       peak: Optional[ResolvedPeak] = None) -> dict:
    """Intervals of +- ``z`` standard deviations about the figures :func:`temperature_figures` reports, from the
    per-voxel standard deviation ``sigma_std`` of ``sigma`` (both (nx, ny, nz)) on voxel centres ``axes``
    (x, y, z [mm]); ``temperature`` maps sigma to T [K] (hot gas has the lower sigma), ``hottest_sigma`` is the
    lowest sigma the field may take (its prior's bound: no hotter bound is read).

    - ``T_peak_interval_K`` [cold, hot]: where the peak is read through the run's resolution (``peak``, a
      resolved :class:`nerif.resolution.ResolvedPeak`): its sigma moved hotter by z u and :data:`REMAINDERS` times
      the correction's next term (what a first order leaves of a core is always hotter), and colder by
      z sqrt(u^2 + b^2), b the correction (a field sharper than the run's resolution model, as exact deflections
      leave it, is corrected too far), u the standard deviation at the peak. Otherwise (no ``peak``, or a core about
      as fine as the run) from the peak voxel's sigma moved colder by z sqrt(u^2 + b^2) to ``sigma - b`` moved
      hotter by as much, b = G sigma - sigma there (G a Gaussian blur of ``blur_vox`` voxels, the run's
      resolution): a peak finer than the field resolves is uncertain by about its own difference from its
      surroundings (issue 59: the bunsen flame's 1861 K read 1533 K). On the 13 shared captures (issue 66, two
      seeds) the first held the truth as often as the second, at two thirds of its width.
    - ``T_peak_position_interval_mm`` [[lo, hi]] per axis: the box of the voxels that could be the hottest, those
      whose hot bound (z u, and z sqrt(u^2 + b^2) at a local peak: the hottest of its 3 x 3 x 3 voxels) reaches
      the peak's cold bound.
    - ``flame_volume_interval_cm3`` [least, most]: the voxels above ``hot_K`` with every voxel at its cold, then
      at its hot bound.
    """
    from scipy.ndimage import minimum_filter

    from nerif.resolution import blur_deficit

    voxel_cm3 = voxel_volume_cm3(axes)
    std = np.asarray(sigma_std, dtype=np.float64)
    # a local peak (the lowest sigma of its 3 x 3 x 3 voxels) sharper than its surroundings: its unresolved part
    local_peak = sigma <= minimum_filter(sigma, size=3, mode="nearest")
    unresolved = np.where(local_peak, np.maximum(blur_deficit(sigma, blur_vox), 0.0), 0.0)
    either = np.sqrt(std**2 + unresolved**2)

    def T(s):
        return temperature(np.maximum(s, hottest_sigma))

    hot_bound = T(sigma - unresolved - z * either)
    # the peak's own voxel (several may sit at the prior's bound: T alone cannot tell them apart)
    at = peak.index if peak is not None else np.unravel_index(np.argmax(T(sigma)), sigma.shape)
    cold_peak, hot_peak = float(T(sigma[at] + z * either[at])), float(hot_bound[at])
    if peak is not None and peak.resolved:  # hotter, the correction leaves its rest; colder, it may be all wrong
        cold_peak = float(T(peak.sigma + z * np.hypot(std[at], peak.deficit)))
        hot_peak = float(T(peak.sigma - z * std[at] - REMAINDERS * peak.remainder))
    could = hot_bound >= cold_peak
    could[at] = True
    where = np.argwhere(could)
    half = [abs(a[1] - a[0]) / 2 if len(a) > 1 else 0.0 for a in axes]
    return {"T_peak_interval_K": [cold_peak, hot_peak],
            "T_peak_position_interval_mm": [[float(a[lo]) - h, float(a[hi]) + h] for a, lo, hi, h in
                                            zip(axes, where.min(0), where.max(0), half)],
            "flame_volume_interval_cm3": [float(np.count_nonzero(T(sigma + z * std) > hot_K)) * voxel_cm3,
                                          float(np.count_nonzero(T(sigma - z * std) > hot_K)) * voxel_cm3]}


def within_intervals(figures: dict) -> dict:
    """Whether each true figure (``T_peak_true_K``, ``T_peak_position_true_mm``, ``flame_volume_true_cm3``) lies in
    its reported interval (:func:`reported_intervals`): 1.0 or 0.0 each, where both are known."""
    out = {}
    for interval, true, name in (("T_peak_interval_K", "T_peak_true_K", "T_peak_in_interval"),
                                 ("flame_volume_interval_cm3", "flame_volume_true_cm3", "flame_volume_in_interval")):
        if figures.get(interval) is not None and figures.get(true) is not None:
            lo, hi = figures[interval]
            out[name] = float(lo <= figures[true] <= hi)
    box, at = figures.get("T_peak_position_interval_mm"), figures.get("T_peak_position_true_mm")
    if box is not None and at is not None:
        out["T_peak_position_in_interval"] = float(all(lo <= c <= hi for (lo, hi), c in zip(box, at)))
    return out


def explained_share(fit_rmse: float, none_rmse: float) -> float:
    """The share of measured values (their mean square) a fit explains, ``1 - (fit_rmse / none_rmse)^2``: 1 for a
    perfect fit, 0 for one no better than zero, below 0 for a worse one; ``none_rmse`` the RMS of the values
    themselves (what no fit leaves), positive."""
    return float(1.0 - (fit_rmse / none_rmse) ** 2)
