"""Every file a reconstruction writes: the volumes (``.npz``, ``.vti``), the masks, the sensing record, slice and
curve images, the held-out views' figures and the final metrics (the line a run prints: :mod:`nerif.io.headline`).

The writers take what a run computed (its :class:`nerif.results.Results`, its masks, its scene) and compute no
score of their own; they call nothing of the solver's.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Optional

import matplotlib
import numpy as np

import nerif.io.plots as plots
from nerif.cache import cached_arrays, content_digest, source_digest
from nerif.export import atomic_write, to_uint8, write_npz, write_png, write_vti
from nerif.metrics import temperature_std
from nerif.io.plots import (curves_figure, heldout_figure, masks_figure, measured_figure, png_bytes,
                             profiles_figure, rig_figure, save_figure, sensing_figure, slice_figure)
from nerif.units import VOLUMES

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
                                 scene.ambient.deflection_unit, scene.cameras[0].binning),
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


def rig_index(name: str, default: int) -> int:
    """A camera's place in the rig from its name (``camera 8 (160.0 deg)`` -> 8), else ``default``."""
    m = re.match(r"camera (\d+)", name)
    return int(m.group(1)) if m else default


def camera_file(name: str) -> str:
    """A camera's name as a file name: ``camera 8 (160.0 deg)`` -> ``camera08``; others with every run of
    characters but letters and digits as one ``_``."""
    m = re.match(r"camera (\d+)", name)
    return f"camera{int(m.group(1)):02d}" if m else re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "camera"


def write_volumes(volumes: dict, scene, out_dir: Path) -> None:
    """A run's volumes (``volumes``: name -> (nx, ny, nz), :func:`nerif.results.final_volumes`) as
    ``reconstruction.npz`` and ``reconstruction.vti``, with the grid and the ambient gas."""
    amb, box = scene.ambient, scene.box
    origin = [float(a[0]) for a in box.axes()]
    write_npz(out_dir / "reconstruction.npz", units=VOLUMES, voxel_mm=box.voxel_mm, origin_mm=np.asarray(origin),
              T0=amb.T0, n0=amb.n0, delta_thre=amb.delta_thre, **volumes)
    write_vti(out_dir / "reconstruction.vti", box.voxel_mm, origin, units=VOLUMES, **volumes)


def write_figures(results, scene, out_dir: Path, history: list, losses, title: str,
                  images_from: Optional[int] = None, show=None) -> None:
    """A run's pictures: the slices and profiles of its :class:`~nerif.results.Results` (``title``), its curves
    (``history``, ``losses``; ``images_from``: the iteration the images' stage began at) and each held-out view's
    figure; ``show(name, png)``, where given, is shown the slices and profiles as their files hold them
    (TensorBoard)."""
    vols = results.volumes
    for name, figure in (("slices", slice_figure), ("profiles", profiles_figure)):
        png = png_bytes(volume_slices(vols["sigma"], scene, title, vols.get("sigma_std"), figure))  # drawn once
        atomic_write(out_dir / f"{name}.png", lambda tmp: Path(tmp).write_bytes(png))
        if show is not None:
            show(name, png)
    save_figure(curves_figure(history, losses, images_from, scene.ambient.deflection_unit),
                out_dir / "curves.png")
    for view in results.heldout:
        cam = view.camera
        save_figure(heldout_figure(view.observed, view.predicted, unit=results.heldout_unit,
                                   title=f"held out: {cam.name}", block_px=cam.binning),
                    out_dir / "heldout" / f"{camera_file(cam.name)}.png")
