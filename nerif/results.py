"""A finished run's results, computed where its scores are made, before anything is written: the volumes on the
probe grid and every figure of ``metrics.json`` (the solver's evaluation on its training and held-out rays, the
peak read through the run's resolution, the uncertainty's figures and intervals, what the measurement found).
:mod:`nerif.io.outputs` only writes a :class:`Results`; each figure's unit is declared here or where it is computed.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import torch

from nerif.data.diagnostics import UNBOUNDED_DEG, widest_gap_deg
from nerif.metrics import (flame_share_region, reported_intervals, resolved_peak_figures, temperature_figures,
                           temperature_std, uncertainty_scores, within_intervals)
from nerif.resolution import effective_resolution_mm, resolved_peak
from nerif.solvers.uncertainty import Estimate
from nerif.units import SHARE, SIGMA, declare

log = logging.getLogger(__name__)

INSIDE = "1 (1: the true figure lies in its interval, 0: it does not)"
declare(T_peak_interval_K="K (the peak's 2-standard-deviation interval: [cold, hot])",
        T_peak_position_interval_mm="mm (per axis [lo, hi]: the box of the voxels that could be the hottest)",
        flame_volume_interval_cm3="cm^3 (the flame volume's 2-standard-deviation interval: [least, most])",
        T_peak_in_interval=INSIDE, T_peak_position_in_interval=INSIDE, flame_volume_in_interval=INSIDE,
        T_peak_field_K="K (the field's hottest voxel, before the resolution's correction)",
        T_peak_resolution_K="K (what the run's resolution took off the peak: T_peak_K - T_peak_field_K)",
        resolution_mm="mm (standard deviation of the Gaussian blur of the field's finest cell and the rays' spacing)",
        T_peak_resolved="1 (1: the hot core is wider than the resolution; 0: about as fine, T_peak_K the field's own)")
declare(uncertainty_coverage_1sigma=SHARE, uncertainty_coverage_2sigma=SHARE, uncertainty_coverage_2sigma_core=SHARE,
        uncertainty_spearman="1 (rank correlation)",
        uncertainty_ause="1 (area under the sparsification error, of sigma)",
        uncertainty_ause_random="1 (the same for a random order)",
        uncertainty_calibration_error="1 (mean |observed - nominal| coverage at 10 levels from 0.1 to 0.95)",
        sigma_std_median_flame=SIGMA,
        ray_binning="px (sensor pixels across a ray)", shake_px_max="px (of the full sensor)",
        text=("temperature_note", "deflection_unit", "history_note"),
        containers={"measurement": "(per camera name: its findings, each unit by its name here)"})


@dataclass
class HeldoutView:
    """One held-out view as the run predicts it, for its figure: ``observed`` and ``predicted`` (height, width, 2)
    image displacements [px] where deflections are physical, else (height, width, 3) deflections [sigma]."""

    camera: object
    observed: np.ndarray
    predicted: np.ndarray


@dataclass
class Results:
    """What a finished run hands its writers.

    Attributes:
        volumes: name -> (nx, ny, nz) array on the probe grid (``sigma``; with a known temperature ``T`` [K], ``n``,
            ``delta``; where estimated ``sigma_std``, ``T_std`` [K], ``views_seeing``; with a truth ``T_true`` [K]),
            each unit in :data:`nerif.units.VOLUMES`.
        metrics: ``metrics.json``'s figures of the final state (each unit declared where it is computed).
        heldout: each held-out view's observed and predicted picture (drawn only where figures are).
        heldout_unit: their unit, ``px`` or ``sigma``.
    """

    volumes: dict
    metrics: dict
    heldout: list = field(default_factory=list)
    heldout_unit: str = "px"


def final_volumes(solver, scene, estimate: Estimate) -> dict:
    """The finished solver's volumes (``sigma``) and those its uncertainty found (``estimate``), with the
    temperature, refractive index, delta and the temperature's standard deviation where a temperature is known, and
    the truth."""
    amb = scene.ambient
    vols = {**solver.volumes(), **estimate.volumes}
    sigma = vols["sigma"]
    if amb.temperature_known:
        vols.update(T=amb.temperature_from_sigma(sigma), n=amb.n_from_sigma(sigma), delta=sigma * amb.delta_thre)
        if "sigma_std" in vols:
            vols["T_std"] = temperature_std(amb, sigma, vols["sigma_std"])
    if scene.truth_T is not None:
        vols["T_true"] = scene.truth_T
    return vols


def results(solver, scene, vols: dict, estimate: Estimate, *, flame_above_K: float, figures: bool = True) -> Results:
    """Every result of a finished ``solver`` on ``scene`` with its volumes ``vols`` (:func:`final_volumes`; the
    flame's volume: where T is above ``flame_above_K`` [K]) and what its uncertainty found (``estimate``: its
    report's figures); ``figures``: the held-out views' pictures kept for drawing."""
    final = dict(solver.history[-1]) if solver.history else solver.evaluate()
    final.pop("iteration", None)
    final.update(solver.evaluation.view_misfits(solver.predict))
    contradicted = solver.evaluation.contradicted(final)
    if contradicted:
        log.warning("%s", contradicted)
    heldout, failed = [], ""
    if scene.heldout is not None:
        errors, heldout = heldout_results(solver, figures)  # every held-out ray, not the evaluation subset
        final.update(errors)
        final["history_note"] = ("history follows the errors on a fixed subset of rays (metrics.eval_rays_per_view "
                                 "per view); the final heldout_* figures use every held-out ray")
        failed = solver.evaluation.failed(final)
        for said in (failed, "" if failed else solver.evaluation.unexplained(final)):
            if said:
                log.warning("%s", said)
    final.update(run_figures(solver, scene, vols["sigma"], failed))
    final.update(estimate.report)
    final.update(peak_and_uncertainty(solver, scene, vols, flame_above_K, final.get("warnings", [])))
    if scene.sensing is not None:
        final.update(scene.sensing.report())
    final.update(measurement_report(scene, solver.shakes_px()))
    if scene.ambient.temperature_known:
        final["temperature_note"] = ("temperature from n assuming an air-dominated gas of fixed composition "
                                     "(n - 1 = T0 (n0 - 1) / T)")
    return Results(vols, final, heldout, "px" if solver.evaluation.physical else "sigma")


def heldout_results(solver, figures: bool) -> tuple[dict, list]:
    """The errors of the finished field on every held-out ray, and (``figures``) each held-out view's observed and
    predicted picture."""
    ev = solver.evaluation
    pred = ev.heldout_predictions(solver.predict)
    views = [HeldoutView(cam, obs, predicted)
             for cam, (obs, predicted) in zip(ev.scene.heldout.cameras, ev.heldout_images(pred))] if figures else []
    return ev.heldout_errors(solver.predict, every=True, pred=pred), views


def run_figures(solver, scene, sigma: np.ndarray, failed: str) -> dict:
    """What the run was and did: its times, history, settings, the ray grid, what the solver decided from the data
    and how near the field came to its prior's bounds (``failed``: the held-out views' failure, if any)."""
    out = {} if scene.ambient.temperature_known else {
        "deflection_unit": "sigma (the data are deflections of sigma; no temperature is inferred)"}
    out.update(solver.timing())
    out["wall_time_s"] = solver.train_seconds
    out["history"] = solver.history
    out.update(solver.labels)
    out["ray_binning"] = int(scene.cameras[0].binning)  # sensor pixels across a ray
    out.update(solver.report)
    out.update(solver.saturation(sigma, failed))
    return out


def peak_and_uncertainty(solver, scene, vols: dict, flame_above_K: float, warnings: list) -> dict:
    """The temperature's figures, the peak read through the run's resolution (a core about as fine as it said in
    one sentence, added to ``warnings``), the uncertainty's figures and the intervals of the peak, its position and
    the flame's volume."""
    amb, box, sigma = scene.ambient, scene.box, vols["sigma"]
    lowest = solver.interval[0] if solver.interval is not None else float(sigma.min())
    resolution = effective_resolution_mm(solver.cell_mm, scene.ray_spacing_mm)
    out: dict = {}
    if amb.temperature_known:
        out.update(temperature_figures(vols["T"], box.axes(), flame_above_K, scene.truth_T))
        peak = resolved_peak(sigma, resolution, box.voxel_mm, lowest, correct=scene.displacements is not None)
        out.update(resolved_peak_figures(peak, amb.temperature_from_sigma, out.get("T_peak_true_K")))
        if not peak.resolved:
            said = unresolved_words(out)
            log.warning("%s", said)
            out["warnings"] = [*warnings, said]
    if "sigma_std" in vols:
        out.update(uncertainty_report(vols, scene))
        if amb.temperature_known:
            out.update(reported_intervals(sigma, vols["sigma_std"], amb.temperature_from_sigma, box.axes(),
                                          flame_above_K, lowest, blur_vox=resolution / box.voxel_mm, peak=peak))
            if widest_gap_deg(scene.cameras) > UNBOUNDED_DEG:  # no view bounds a core's peak from above
                prior = float(amb.temperature_from_sigma(np.float64(lowest)))
                out["T_peak_interval_K"][1] = max(out["T_peak_interval_K"][1], prior)
            out.update(within_intervals(out))
    return out


def uncertainty_report(vols: dict, scene) -> dict:
    """``metrics.json``'s uncertainty figures: the median ``T_std`` [K] (``sigma_std`` where no temperature is
    inferred) over the reconstruction's flame (:func:`nerif.metrics.flame_share_region`), and where a truth is known
    :func:`nerif.metrics.uncertainty_scores` (``uncertainty_`` + its names)."""
    sigma, std = vols["sigma"], vols["sigma_std"]
    flame = flame_share_region(sigma, empty=True)
    out = {"sigma_std_median_flame": float(np.median(std[flame]))}
    if "T_std" in vols:
        out["T_std_median_flame_K"] = float(np.median(vols["T_std"][flame]))
        hottest = np.unravel_index(np.argmax(vols["T"]), sigma.shape)  # the voxel of T_peak_K
        out["T_std_at_peak_K"] = float(vols["T_std"][hottest])
    if scene.truth_T is not None:
        truth = scene.ambient.sigma_from_temperature(scene.truth_T)
        out.update({f"uncertainty_{k}": v for k, v in uncertainty_scores(sigma, std, truth).items()})
    return out


def measurement_report(scene, refined: Optional[torch.Tensor] = None) -> dict:
    """What the measurement stage found in every view, training and held out (``measurement``: camera name ->
    its figures), and the largest shake taken off any view (``shake_px_max``, px of the full sensor); empty for
    data not measured from images. ``refined``: (V, 2) the training views' shakes as the fit refined them [px of
    the full sensor] (``shake_refined_px`` beside the measured ``shake_px``), or None."""
    per_view = {}
    for s in (scene, scene.heldout):
        if s is not None and s.findings:
            for cam, found in zip(s.cameras, s.findings):
                per_view[cam.name] = found.report()
    if not per_view:
        return {}
    if refined is not None:
        for cam, shake in zip(scene.cameras, refined.tolist()):
            per_view[cam.name]["shake_refined_px"] = [float(x) for x in shake]
            log.info("%s: shake refined with the field to (%+.3f, %+.3f) px (measured (%+.3f, %+.3f))", cam.name,
                     *shake, *per_view[cam.name]["shake_px"])
    shakes = [float(np.hypot(*f["shake_px"])) for f in per_view.values() if "shake_px" in f]
    return {"measurement": per_view, **({"shake_px_max": max(shakes)} if shakes else {})}


def unresolved_words(m: dict) -> str:
    """The sentence for a hot core about as fine as the run resolves (:mod:`nerif.resolution`)."""
    return (f"the hottest core is about as fine as this run resolves ({m['resolution_mm']:.2f} mm, from the field's "
            f"finest cell and the rays' spacing), or a spike where streaks of a few views cross: its peak, "
            f"{m['T_peak_K']:.0f} K as the field reads it, cannot be read more closely (a core that fine reads cold); "
            "finer rays (data.binning) or a finer field (field.finest_resolution) resolve it where the data carry it")
