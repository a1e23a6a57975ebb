"""Every file a reconstruction writes: the volumes (``.npz``, ``.vti``), the masks, the sensing record, slice and
curve images, the held-out views' figures, the final metrics, and the one summary line a run prints.

The writers take a finished solver (its ``reconstruction()``, ``history``, ``evaluation``, ``timing()``) and
its scene; they compute no score of their own: :class:`nerif.evaluation.Evaluation` does.
"""
from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Optional

import matplotlib
import numpy as np
import torch

import nerif.io.plots as plots
from nerif.cache import cached_arrays, content_digest, source_digest
from nerif.export import atomic_write, to_uint8, write_npz, write_png, write_vti
from nerif.metrics import (flame_share_region, reported_intervals, resolved_peak_figures, temperature_figures,
                           uncertainty_scores, within_intervals)
from nerif.resolution import effective_resolution_mm, resolved_peak
from nerif.io.plots import (curves_figure, heldout_figure, masks_figure, measured_figure, png_bytes,
                             profiles_figure, rig_figure, save_figure, sensing_figure, slice_figure)
from nerif.units import SHARE, SIGMA, VOLUMES, declare

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
# the files every run writes (held-out figures, masks and sensing pictures beside them where there are any)
RESULTS = ("reconstruction.npz", "reconstruction.vti", "slices.png", "profiles.png", "curves.png", "metrics.json")


def write_masks(masks, scene, out_dir: Path, figures: bool = True) -> None:
    """2-D masks as PNGs (one per view, 255 inside), ``masks/masks2d.png`` (every view's mask over its measured
    deflections; ``figures``: drawn), and the 3-D mask as a volume."""
    for v, img in enumerate(masks.images or []):
        write_png(out_dir / "masks" / f"mask2d_view{v:02d}.png", img.astype(np.uint8) * 255)
    if masks.images and figures:
        eps = scene.eps.detach().cpu().double().numpy()
        values = [scene.view_image(v, np.linalg.norm(eps[scene.view_slice(v)], axis=-1), np.nan)
                  for v in range(scene.n_views)]
        save_figure(masks_figure(values, list(masks.images), [c.name for c in scene.cameras],
                                 "rad" if scene.ambient.temperature_known else "sigma", scene.cameras[0].binning),
                    out_dir / "masks" / "masks2d.png")
    if masks.volume is not None:
        origin = [float(a[0]) for a in scene.box.axes()]
        write_npz(out_dir / "mask3d.npz", units=VOLUMES, mask=masks.volume, voxel_mm=scene.box.voxel_mm,
                  origin_mm=np.asarray(origin))
        write_vti(out_dir / "mask3d.vti", scene.box.voxel_mm, origin, units=VOLUMES, mask=masks.volume.astype(np.float32))


def write_rig(scene, out_dir: Path) -> None:
    """``rig.png`` (:func:`~nerif.io.plots.rig_figure`): every view, training and held out, in the rig's order,
    seen from above with its angle and the sense its order turns, beside each measured view's displacement
    magnitude with the probe box and the world's axes drawn where the rig puts them: a mirrored or reversed rig
    shows there before the fit."""
    views = [*scene.views, *(scene.heldout.views if scene.heldout is not None else [])]
    order = np.argsort([rig_index(v.camera.name, k) for k, v in enumerate(views)], kind="stable")
    views = [views[k] for k in order]
    held = {k for k, j in enumerate(order) if j >= scene.n_views}

    def picture(view):
        if view.measured_px is None:
            return None
        return np.linalg.norm(np.nan_to_num(view.measured_px), axis=-1), "|displacement| [px]"

    save_figure(rig_figure([v.camera for v in views], scene.box, held, [picture(v) for v in views]),
                out_dir / "rig.png")


def write_sensing(scene, out_dir: Path, causes: tuple = (), cache_dir=None, figures: bool = True) -> None:
    """Each measured view, training and held out: ``sensing/cameraNN_measured.png``, its reference with what the
    measurement stage left out coloured by cause (``causes``: the names of the stage's codes,
    :data:`nerif.sensing.measurement.CAUSES`) and its displacement magnitude; kept in ``cache_dir`` (None: drawn
    every time) keyed by what it shows, so that another run of the same measurement copies it. Realistic sensing,
    per view: the reference and distorted images (8-bit PNG, as a camera would save them) and a figure of images
    and displacements. ``figures``: the figures drawn (the images are data, written either way)."""
    for s in ((scene, scene.heldout) if figures else ()):
        for view in (s.views if s is not None and causes else ()):
            if view.left_out is None or view.images is None:
                continue
            reference = view.images.reference.cpu().numpy()
            kept = 100 * float(np.mean(view.left_out == 0))
            title = (f"{view.camera.name}: the measurement kept {kept:.1f} % of its rays (displacements in px of the "
                     "full sensor)")
            payload = {"picture": "measured", "title": title, "causes": list(causes), "code": source_digest(plots),
                       "matplotlib": matplotlib.__version__,
                       **{k: content_digest(np.asarray(a)) for k, a in (("reference", reference),
                          ("displacement", view.measured_px), ("left_out", view.left_out))}}
            png = cached_arrays(cache_dir, "picture", payload, lambda: {"png": np.frombuffer(png_bytes(
                measured_figure(reference, view.measured_px, view.left_out, causes, title)), np.uint8)})["png"]
            atomic_write(out_dir / "sensing" / f"{camera_file(view.camera.name)}_measured.png",
                         lambda tmp: Path(tmp).write_bytes(png.tobytes()))
    rec = scene.sensing
    if rec is None:
        return
    for v, (view, u_true) in enumerate(zip(scene.views, rec.u_true)):
        reference, distorted = (to_uint8(im.cpu().numpy()) for im in (view.images.reference, view.images.distorted))
        write_png(out_dir / "sensing" / f"reference_view{v:02d}.png", reference)
        write_png(out_dir / "sensing" / f"distorted_view{v:02d}.png", distorted)
        if not figures:
            continue
        u_est = view.measured_px / np.float32(view.images.camera.binning)  # px of the images' grid, as u_true
        save_figure(sensing_figure(reference, distorted, u_true, u_est,
                                   title=f"{view.camera.name}: displacement RMSE of the flow "
                                         f"{rec.displacement_rmse_px:.3f} px (all views)"),
                    out_dir / "sensing" / f"view{v:02d}.png")


def volume_slices(sigma: np.ndarray, scene, title: str, sigma_std: Optional[np.ndarray] = None,
                  figure=slice_figure):
    """``figure`` (:func:`~nerif.io.plots.slice_figure`, :func:`~nerif.io.plots.profiles_figure`) of the temperature
    (with the truth where known), or of sigma when no temperature can be inferred; with their standard deviation
    where estimated (``sigma_std``)."""
    if not scene.ambient.temperature_known:
        return figure(sigma, scene.box, None, title, unit="sigma", std=sigma_std)
    std = temperature_std(scene.ambient, sigma, sigma_std) if sigma_std is not None else None
    return figure(scene.ambient.temperature_from_sigma(sigma), scene.box, scene.truth_T, title, std=std)


def temperature_std(ambient, sigma: np.ndarray, sigma_std: np.ndarray) -> np.ndarray:
    """The standard deviation of T [K] of one of sigma, to first order: ``|dT/dsigma| sigma_std``."""
    h = 1e-4
    slope = (ambient.temperature_from_sigma(sigma + h) - ambient.temperature_from_sigma(sigma - h)) / (2 * h)
    return np.abs(slope) * sigma_std


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


def rig_index(name: str, default: int) -> int:
    """A camera's place in the rig from its name (``camera 8 (160.0 deg)`` -> 8), else ``default``."""
    m = re.match(r"camera (\d+)", name)
    return int(m.group(1)) if m else default


def camera_file(name: str) -> str:
    """A camera's name as a file name: ``camera 8 (160.0 deg)`` -> ``camera08``; others with every run of
    characters but letters and digits as one ``_``."""
    m = re.match(r"camera (\d+)", name)
    return f"camera{int(m.group(1)):02d}" if m else re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "camera"


def write_heldout(solver, out_dir: Path, figures: bool = True) -> dict:
    """Predictions on every held-out ray: their errors, and per view (``figures``) a figure of observed, predicted
    and difference (image displacements [px] where deflections are physical, else deflections)."""
    ev = solver.evaluation
    pred = ev.heldout_predictions(solver.predict)
    unit = "px" if ev.physical else "sigma"
    for v, (obs, predicted) in enumerate(ev.heldout_images(pred) if figures else ()):
        cam = ev.scene.heldout.cameras[v]
        save_figure(heldout_figure(obs, predicted, unit=unit, title=f"held out: {cam.name}", block_px=cam.binning),
                    out_dir / "heldout" / f"{camera_file(cam.name)}.png")
    return ev.heldout_errors(solver.predict, every=True, pred=pred)


def write_outputs(solver, scene, out_dir: Path, losses, *, flame_above_K: float, show=None,
                  figures: bool = True) -> dict:
    """Volumes (.npz, .vti), slice, profile and curve PNGs, held-out figures (``figures``: drawn, else the data
    files alone), and the metrics of the final state (the flame's volume: where T is above ``flame_above_K`` [K]);
    ``show(name, png)``, where given, is shown the slices and profiles as their files hold them (TensorBoard)."""
    amb, box = scene.ambient, scene.box
    vols = dict(solver.volumes())
    sigma = vols["sigma"]
    if amb.temperature_known:
        vols.update(T=amb.temperature_from_sigma(sigma), n=amb.n_from_sigma(sigma), delta=sigma * amb.delta_thre)
        if "sigma_std" in vols:
            vols["T_std"] = temperature_std(amb, sigma, vols["sigma_std"])
    if scene.truth_T is not None:
        vols["T_true"] = scene.truth_T
    origin = [float(a[0]) for a in box.axes()]
    write_npz(out_dir / "reconstruction.npz", units=VOLUMES, voxel_mm=box.voxel_mm, origin_mm=np.asarray(origin),
              T0=amb.T0, n0=amb.n0, delta_thre=amb.delta_thre, **vols)
    write_vti(out_dir / "reconstruction.vti", box.voxel_mm, origin, units=VOLUMES, **vols)
    label = " + ".join(str(v) for k, v in solver.labels.items() if k != "lam")
    title = f"{label}, {solver.iteration} iterations"
    for name, figure in (("slices", slice_figure), ("profiles", profiles_figure)) if figures else ():
        png = png_bytes(volume_slices(sigma, scene, title, vols.get("sigma_std"), figure))  # drawn once
        atomic_write(out_dir / f"{name}.png", lambda tmp: Path(tmp).write_bytes(png))
        if show is not None:
            show(name, png)
    if figures:
        save_figure(curves_figure(solver.history, losses, solver.report.get("images_from_iteration"),
                                  "rad" if amb.temperature_known else "sigma"), out_dir / "curves.png")
    final = dict(solver.history[-1]) if solver.history else solver.evaluate()
    final.pop("iteration", None)
    final.update(solver.evaluation.view_misfits(solver.predict))
    contradicted = solver.evaluation.contradicted(final)
    if contradicted:
        log.warning("%s", contradicted)
    failed = ""
    if scene.heldout is not None:
        final.update(write_heldout(solver, out_dir, figures))  # every held-out ray, not the evaluation subset
        final["history_note"] = ("history follows the errors on a fixed subset of rays (metrics.eval_rays_per_view "
                                 "per view); the final heldout_* figures use every held-out ray")
        failed = solver.evaluation.failed(final)
        for said in (failed, "" if failed else solver.evaluation.unexplained(final)):
            if said:
                log.warning("%s", said)
    if not amb.temperature_known:
        final["deflection_unit"] = "sigma (the data are deflections of sigma; no temperature is inferred)"
    final.update(solver.timing())
    final["wall_time_s"] = solver.train_seconds
    final["history"] = solver.history
    final.update(solver.labels)
    final["ray_binning"] = int(scene.cameras[0].binning)  # sensor pixels across a ray
    final.update(solver.report)
    final.update(solver.saturation(sigma, failed))
    lowest = solver.interval[0] if hasattr(solver, "interval") else float(sigma.min())
    resolution = effective_resolution_mm(solver.cell_mm, scene.ray_spacing_mm)
    if amb.temperature_known:
        final.update(temperature_figures(vols["T"], box.axes(), flame_above_K, scene.truth_T))
        peak = resolved_peak(sigma, resolution, box.voxel_mm, lowest, correct=scene.displacements is not None)
        final.update(resolved_peak_figures(peak, amb.temperature_from_sigma, final.get("T_peak_true_K")))
        if not peak.resolved:
            said = unresolved_words(final)
            log.warning("%s", said)
            final["warnings"] = [*final.get("warnings", []), said]
    if "sigma_std" in vols:
        final.update(uncertainty_report(vols, scene))
        if amb.temperature_known:
            final.update(reported_intervals(sigma, vols["sigma_std"], amb.temperature_from_sigma, box.axes(),
                                            flame_above_K, lowest, blur_vox=resolution / box.voxel_mm))
            final.update(within_intervals(final))
    if scene.sensing is not None:
        final.update(scene.sensing.report())
    final.update(measurement_report(scene, solver.shakes_px()))
    if amb.temperature_known:
        final["temperature_note"] = ("temperature from n assuming an air-dominated gas of fixed composition "
                                     "(n - 1 = T0 (n0 - 1) / T)")
    return final


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


def temperature_words(m: dict) -> str:
    """The summary line's temperatures: the peak (+- one standard deviation where estimated) and where it is, the
    true peak and the peak's error where a truth is known, and the flame's volume."""
    std = f" +- {m['T_std_at_peak_K']:.0f} K" if m.get("T_std_at_peak_K") is not None else " K"
    if m.get("T_peak_interval_K") is not None:  # the peak's own interval (nerif.metrics.reported_intervals)
        std = " K (2 std: {:.0f}-{:.0f})".format(*m["T_peak_interval_K"])
    if m.get("T_peak_field_K") is not None and m.get("resolution_mm") is not None:
        std = f"{std} read through {m['resolution_mm']:.2f} mm of resolution (the field's {m['T_peak_field_K']:.0f} K)"
    where = m.get("T_peak_position_mm")
    at = f" at ({', '.join(f'{c:.1f}' for c in where)}) mm" if isinstance(where, list) else ""
    true = (f" (true {m['T_peak_true_K']:.0f} K, {m['T_peak_error_K']:+.0f} K)"
            if m.get("T_peak_true_K") is not None else "")
    volume = ""
    if m.get("flame_volume_cm3") is not None and m.get("flame_volume_above_K") is not None:
        spread = (" (2 std: {:.3g}-{:.3g})".format(*m["flame_volume_interval_cm3"])
                  if m.get("flame_volume_interval_cm3") is not None else "")
        volume = f", {m['flame_volume_cm3']:.3g} cm3{spread} above {m['flame_volume_above_K']:.0f} K" + (
            f" (true {m['flame_volume_true_cm3']:.3g})" if m.get("flame_volume_true_cm3") is not None else "")
    return f"peak T {m['T_peak_K']:.0f}{std}{at}{true}{volume}"


def summary_line(m: dict, out_dir: Path, prefix: str = "") -> str:
    """One line of the run's headline figures, each named as in ``metrics.json`` (after ``prefix``)."""
    def known(k):
        return m.get(k) is not None and np.isfinite(m[k])

    parts = []
    if known("temperature_rmse_K"):
        flame = f" (flame {m['temperature_rmse_flame_K']:.1f} K)" if known("temperature_rmse_flame_K") else ""
        parts.append(f"T RMSE {m['temperature_rmse_K']:.1f} K{flame}")
    if known("T_peak_K"):
        parts.append(temperature_words(m))
    unit = "sigma" if "deflection_unit" in m else "rad"
    parts.append(f"deflection RMSE {m['deflection_rmse']:.3g} {unit}")
    if known("heldout_deflection_rmse"):
        def psnr(k: str) -> str:
            return f"PSNR {m[k]:.1f} dB" if known(k) else "PSNR undefined (no deflection seen)"

        held = [f"{100 * m['heldout_explained']:.0f} % of its displacements explained"] \
            if known("heldout_explained") else []
        held.append(f"deflection RMSE {m['heldout_deflection_rmse']:.3g} {unit}, {psnr('heldout_psnr_db')}")
        if known("heldout_displacement_rmse_px"):
            held.append(f"displacement RMSE {m['heldout_displacement_rmse_px']:.3g} px, "
                        f"{psnr('heldout_displacement_psnr_db')}")
        if known("heldout_photometric_rmse"):
            ref = (f" (the flow's {100 * m['heldout_photometric_rmse_flow']:.2f} %, none "
                   f"{100 * m['heldout_photometric_rmse_none']:.2f} %)" if known("heldout_photometric_rmse_flow") else "")
            held.append(f"image residual {100 * m['heldout_photometric_rmse']:.2f} % of full range{ref}")
        parts.append("held out: " + "; ".join(held))
    if m.get("flow_stage") and m.get("images_stage"):  # the held-out views chose between the flow's field and the images'
        whose = "the images'" if m["data_term_kept"] == "images" else "the flow's"
        if "heldout_image_misfit" in m["images_stage"] and "heldout_image_misfit" in m["flow_stage"]:
            flow, images = (100 * m[k]["heldout_image_misfit"] for k in ("flow_stage", "images_stage"))
            parts.append(f"kept {whose} field (held-out image residual: images {images:.3g}, flow {flow:.3g} % of "
                         "full range)")
        else:
            flow, images = m["flow_stage"]["heldout_misfit"], m["images_stage"]["heldout_misfit"]
            unit = "sigma" if "deflection_unit" in m else "px"
            parts.append(f"kept {whose} field (held out: images {images:.3g}, flow {flow:.3g} {unit})")
    elif m.get("data_term_kept"):  # a series: how often each was kept
        parts.append(f"field kept: {m['data_term_kept']}")
    if known("T_std_median_flame_K"):
        parts.append(f"uncertainty in the flame {m['T_std_median_flame_K']:.0f} K median (1 std)")
    parts += [f"WARNING: {w}" for w in m.get("warnings", [])]
    resumed = m["wall_time_s"] > m["total_time_s"]  # training of earlier sessions counts, this process's time not
    parts.append(f"{m['iterations']} it: {m['wall_time_s']:.0f} s training{' over every session' if resumed else ''} "
                 f"({m['ms_per_iteration']:.1f} ms/it), {m['total_time_s']:.0f} s in all"
                 f"{' this session' if resumed else ''}")
    return "nerif: " + prefix + " | ".join(parts) + f" | {out_dir}"
