"""One reconstruction from a resolved config (the steady scene, or one frame of a time series): build the parts,
train, write every output of the run."""
from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from omegaconf import DictConfig

from nerif.configs import group
from nerif.data import DATASETS
from nerif.data.scene import view_directions
from nerif.io.export import write_json, write_npz, write_png, write_vti
from nerif.io.plots import curves_figure, heldout_figure, save_figure, sensing_figure, slice_figure
from nerif.masks import MASKS
from nerif.sensing.displacement import view_displacements
from nerif.solvers import SOLVERS

log = logging.getLogger(__name__)


def resuming(setting) -> bool:
    """Whether a run continues from its own folder: ``train.resume=auto``, or a requeued Slurm job
    (``SLURM_RESTART_COUNT`` above 0: a preempted or timed-out job of a multirun through submitit) without an
    explicit checkpoint."""
    return setting == "auto" or (setting is None and int(os.environ.get("SLURM_RESTART_COUNT", "0") or 0) > 0)


def checkpoint_to_resume(setting, own: Path) -> Optional[Path]:
    """The checkpoint a run continues from: ``train.resume`` when it is a path; where :func:`resuming`, the run
    folder's own ``checkpoint.pt`` when there is one; else none."""
    if resuming(setting):
        return own if own.is_file() else None
    return Path(setting) if setting else None


def reconstruct(cfg: DictConfig, out_dir: Path, device: torch.device, frame: Optional[int] = None,
                start_from: Optional[Path] = None, t_start: Optional[float] = None, about: Optional[dict] = None,
                resume_hint: Optional[str] = None) -> dict:
    """One reconstruction (of ``frame`` of a time series, or of the steady scene) into ``out_dir``: build the
    parts, train (from the state of ``start_from``, a checkpoint of the previous frame, unless the run resumes
    its own), write every output (``about``: entries added to its ``metrics.json``). Returns the final metrics.
    ``resume_hint``: how to continue after an interruption (default: from this run's checkpoint)."""
    t_start = time.perf_counter() if t_start is None else t_start
    torch.manual_seed(cfg.seed)
    # every check that can fail happens here, before any training; the solver checks its settings before any data
    solver = SOLVERS.build(group(cfg, "solver"))
    extra = {} if frame is None else {"frame": frame}
    scene = DATASETS.build(group(cfg, "data"), device=str(device), **extra)
    masks = MASKS.build(group(cfg, "mask"), scene=scene)
    solver.setup(scene, masks)
    rig_warnings = ill_posed(scene)
    tc = cfg.train
    write_masks(masks, scene, out_dir)
    write_sensing(scene, out_dir)
    checkpoint = out_dir / "checkpoint.pt"
    resume = checkpoint_to_resume(tc.resume, checkpoint)
    if resume is not None:
        solver.load(resume)
        log.info("resumed from %s at iteration %d", resume, solver.iteration)
    elif start_from is not None:
        solver.start_from(start_from)
        log.info("warm start from %s", start_from)
    setup_s = time.perf_counter() - t_start

    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(log_dir=str(out_dir / "tensorboard"))
    losses: list[tuple[int, float]] = []

    def on_step(it: int, terms: dict) -> None:
        losses.append((it, terms["loss"]))
        if it % 10 == 0:
            for k, v in terms.items():
                writer.add_scalar(f"train/{k}", v, it)

    def on_eval(m: dict) -> None:
        it = m["iteration"]
        for k, v in m.items():
            if k != "iteration" and isinstance(v, (int, float)):  # None: not defined here (no flame)
                writer.add_scalar(f"eval/{k}", v, it)
        if it % tc.image_every == 0 or it == solver.iterations:
            writer.add_figure("slices", volume_slices(solver.reconstruction(), scene, f"iteration {it}"), it)
        writer.flush()

    log.info("%s: %d views, %d rays; %s, device %s", cfg.data.name, scene.n_views, len(scene.dirs),
             ", ".join(f"{k} {v}" for k, v in solver.labels.items()), device)
    try:
        solver.fit(checkpoint_every=tc.checkpoint_every, checkpoint_every_s=tc.checkpoint_every_s,
                   checkpoint=checkpoint, on_eval=on_eval, on_step=on_step, progress=tc.progress,
                   resume_hint=resume_hint)
    finally:
        writer.close()

    metrics = write_outputs(solver, scene, out_dir, losses)
    metrics["warnings"] = rig_warnings + metrics.get("warnings", [])
    metrics.update(setup_time_s=setup_s, device=str(device) if device.type == "cpu" else torch.cuda.get_device_name(device),
                   cpu_threads=torch.get_num_threads())
    if device.type == "cuda":
        metrics["gpu_peak_memory_gib"] = torch.cuda.max_memory_allocated(device) / 2**30
    metrics["total_time_s"] = time.perf_counter() - t_start
    metrics.update(about or {})
    write_json(metrics, out_dir / "metrics.json")
    print(summary_line(metrics, out_dir), flush=True)
    return metrics


def ill_posed(scene) -> list[str]:
    """Warnings (logged, and returned for ``metrics.json``) where the data cannot fix a 3-D field."""
    n = view_directions(scene.cameras)
    if n >= 3:
        return []
    msg = (f"ill-posed: the {scene.n_views} training view(s) look along only {n} distinct direction(s); a 3-D "
           "field needs at least 3, and the reconstruction is not to be trusted away from what they see")
    log.warning("%s", msg)
    return [msg]


def write_masks(masks, scene, out_dir: Path) -> None:
    """2-D masks as PNGs (one per view) and the 3-D mask as a volume."""
    for v, img in enumerate(masks.images or []):
        write_png(out_dir / "masks" / f"mask2d_view{v:02d}.png", img.astype(np.uint8) * 255)
    if masks.volume is not None:
        origin = [float(a[0]) for a in scene.box.axes()]
        write_npz(out_dir / "mask3d.npz", mask=masks.volume, voxel_mm=scene.box.voxel_mm, origin_mm=np.asarray(origin))
        write_vti(out_dir / "mask3d.vti", scene.box.voxel_mm, origin, mask=masks.volume.astype(np.float32))


def write_sensing(scene, out_dir: Path) -> None:
    """Realistic sensing, per view: the reference and distorted images (8-bit PNG, as a camera would save
    them) and a figure of images and displacements."""
    rec = scene.sensing
    if rec is None:
        return
    for v, cam in enumerate(scene.cameras):
        write_png(out_dir / "sensing" / f"reference_view{v:02d}.png", rec["reference"][v])
        write_png(out_dir / "sensing" / f"distorted_view{v:02d}.png", rec["distorted"][v])
        save_figure(sensing_figure(rec, v, title=f"{cam.name}: displacement RMSE of the flow "
                                   f"{float(rec['displacement_rmse_px']):.3f} px (all views)"),
                    out_dir / "sensing" / f"view{v:02d}.png")


def volume_slices(sigma: np.ndarray, scene, title: str):
    """Slices of the temperature (with the truth where known), or of sigma when no temperature can be inferred."""
    if not scene.ambient.temperature_known:
        return slice_figure(sigma, scene.box, None, title, unit="sigma", hot=-1)
    return slice_figure(scene.ambient.temperature_from_sigma(sigma), scene.box, scene.truth_T, title)


def write_heldout(solver, scene, out_dir: Path) -> dict:
    """Predictions on every held-out ray: their errors, and per view a figure of observed, predicted and
    difference (image displacements [px] where deflections are physical, else deflections)."""
    h = scene.heldout
    pred = solver.heldout_predictions()
    physical = h.ambient.temperature_known
    obs_all = view_displacements(h.eps, h.dirs, h.ray_views(), h.cameras) if physical else h.eps
    pred_all = view_displacements(pred, h.dirs, h.ray_views(), h.cameras) if physical else pred
    for v, cam in enumerate(h.cameras):
        sl = h.view_slice(v)
        imgs = [h.view_image(v, vec[sl].detach().cpu().double().numpy(), np.nan) for vec in (obs_all, pred_all)]
        save_figure(heldout_figure(*imgs, unit="px" if physical else "sigma", title=f"held out: {cam.name}"),
                    out_dir / "heldout" / f"view{v:02d}.png")
    return solver.heldout_errors(torch.arange(len(h.dirs), device=h.dirs.device), pred)


def write_outputs(solver, scene, out_dir: Path, losses) -> dict:
    """Volumes (.npz, .vti), slice and curve PNGs, held-out figures, and the metrics of the final state."""
    amb, box = scene.ambient, scene.box
    sigma = solver.reconstruction()
    vols = {"sigma": sigma}
    if amb.temperature_known:
        vols.update(T=amb.temperature_from_sigma(sigma), n=amb.n_from_sigma(sigma), delta=sigma * amb.delta_thre)
    if scene.truth_T is not None:
        vols["T_true"] = scene.truth_T
    origin = [float(a[0]) for a in box.axes()]
    write_npz(out_dir / "reconstruction.npz", voxel_mm=box.voxel_mm, origin_mm=np.asarray(origin), T0=amb.T0, n0=amb.n0,
              delta_thre=amb.delta_thre, **vols)
    write_vti(out_dir / "reconstruction.vti", box.voxel_mm, origin, **vols)
    label = " + ".join(str(v) for k, v in solver.labels.items() if k != "lam")
    save_figure(volume_slices(sigma, scene, f"{label}, {solver.iteration} iterations"), out_dir / "slices.png")
    save_figure(curves_figure(solver.history, losses), out_dir / "curves.png")
    final = dict(solver.history[-1]) if solver.history else solver.evaluate()
    final.pop("iteration", None)
    if scene.heldout is not None:
        final.update(write_heldout(solver, scene, out_dir))  # every held-out ray, not the evaluation subset
    if not amb.temperature_known:
        final["deflection_unit"] = "sigma (the data are deflections of sigma; no temperature is inferred)"
    final.update(solver.timing())
    final["wall_time_s"] = solver.train_seconds
    final["history"] = solver.history
    final.update(solver.labels)
    final.update(solver.report)
    final.update(solver.saturation(sigma))
    if scene.sensing is not None:
        final["displacement_rmse_px"] = float(scene.sensing["displacement_rmse_px"])
        final["circle_of_confusion_px"] = float(scene.sensing["circle_of_confusion_px"])
    if amb.temperature_known:
        final["temperature_note"] = ("temperature from n assuming an air-dominated gas of fixed composition "
                                     "(n - 1 = T0 (n0 - 1) / T)")
    return final


def summary_line(m: dict, out_dir: Path, prefix: str = "") -> str:
    """One line of the run's headline figures, each named as in ``metrics.json`` (after ``prefix``)."""
    def known(k):
        return m.get(k) is not None and np.isfinite(m[k])

    parts = []
    if known("temperature_rmse_K"):
        flame = f" (flame {m['temperature_rmse_flame_K']:.1f} K)" if known("temperature_rmse_flame_K") else ""
        parts.append(f"T RMSE {m['temperature_rmse_K']:.1f} K{flame}")
    unit = "sigma" if "deflection_unit" in m else "rad"
    parts.append(f"deflection RMSE {m['deflection_rmse']:.3g} {unit}")
    if known("heldout_deflection_rmse"):
        held = [f"deflection RMSE {m['heldout_deflection_rmse']:.3g} {unit}, PSNR {m['heldout_psnr_db']:.1f} dB"]
        if known("heldout_displacement_rmse_px"):
            held.append(f"displacement RMSE {m['heldout_displacement_rmse_px']:.3g} px, PSNR "
                        f"{m['heldout_displacement_psnr_db']:.1f} dB")
        parts.append("held out: " + "; ".join(held))
    parts += [f"WARNING: {w}" for w in m.get("warnings", [])]
    parts.append(f"{m['iterations']} it: {m['wall_time_s']:.0f} s training ({m['ms_per_iteration']:.1f} ms/it), "
                 f"{m['total_time_s']:.0f} s in all")
    return "nerif: " + prefix + " | ".join(parts) + f" | {out_dir}"
