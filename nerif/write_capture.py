"""Write a capture folder (images + ``rig.yaml``) from a synthetic scene sensed realistically.

    python -m nerif.write_capture PATH [config overrides]
    python -m nerif.write_capture /tmp/capture phantom=axisymmetric rig.n_cameras=8
    python -m nerif.write_capture /tmp/sequence phantom=flicker data.frames=8   # a time series, 250 frames/s
    python -m nerif.write_capture /tmp/capture --overwrite                      # replace an earlier capture whole

The folder is what ``python -m nerif data=capture data.root=PATH`` reads: the same loop as a real experiment.
"""
from __future__ import annotations

import argparse
import logging
import os
import shutil
import sys
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from hydra.errors import HydraException

from nerif.app import unexpected
from nerif.configs import check_complete, check_kinds, compose, group, group_choices, unknown_override
from nerif.data import DATASETS
from nerif.sequence import frames_of
from nerif.data.rig_file import CALIBRATED_VERSION, read_rig, write_rig
from nerif.data.scene import Scene
from nerif.geometry import Camera
from nerif.export import atomic_write, to_uint8, write_npz, write_png
from nerif.units import VOLUMES
from nerif.sensing.optics import probe_distance_mm

log = logging.getLogger("nerif")
TRUTH_FILE = "volume.npz"  # the rendered truth, beside the images (a series: in each frame's folder)


def write_capture(scenes, root: Path, heldout: Optional[list] = None, times: Optional[list] = None) -> Path:
    """Write synthetic scenes sensed realistically as a capture folder (8-bit images and ``rig.yaml``).

    Args:
        scenes: a scene from :func:`nerif.data.synthetic.synthetic` with ``sensing=realistic`` (its images), or an
            iterable of such scenes of one rig, the frames of a time series at ``times`` [s] (each is written
            as it comes, to ``frame_KKKK/``); the rig file describes the first scene's cameras.
        heldout: views never trained on (default: the last).
    """
    root = Path(root)
    series = times is not None
    scenes = [scenes] if isinstance(scenes, Scene) else scenes
    listed, first = [], None
    for k, scene in enumerate(scenes):
        if scene.images is None:
            raise ValueError("writing a capture needs images: use data.sensing=realistic")
        dist = [to_uint8(im.distorted.cpu().numpy()) for im in scene.images]  # as the camera saved them
        folder = f"frame_{k:04d}/" if series else ""
        write_truth(scene, root / f"{folder}{TRUTH_FILE}")
        listed.append([f"{folder}distorted_{v:02d}.png" for v in range(len(dist))])
        for v, name in enumerate(listed[-1]):
            write_png(root / name, dist[v])
        if first is None:
            first = scene
            for v, im in enumerate(scene.images):
                write_png(root / f"reference_{v:02d}.png", to_uint8(im.reference.cpu().numpy()))
    if first is None or (series and len(listed) != len(times)) or (not series and len(listed) != 1):
        raise ValueError(f"{len(listed)} scene(s) for {len(times) if series else 1} frame(s)")
    n, (H, W) = first.n_views, first.images[0].reference.shape
    if any(c.distortion is not None or c.centre_px is not None or c.aspect != 1.0 for c in first.cameras):
        if series:
            raise ValueError("a time series through a calibrated rig is not written yet: write one state at a time")
        return write_calibrated(first, root, listed[0], heldout)
    cam = first.cameras[0].full_sensor
    angles = [round(float(np.degrees(np.arctan2(c.position[0], c.position[2]))), 6) for c in first.cameras]
    views = {"angles_deg": angles, "references": [f"reference_{v:02d}.png" for v in range(n)]}
    blocks = {"camera": {"focal_mm": float(cam.focal_mm), "pitch_um": round(cam.pitch_mm * 1e3 * cam.width / W, 9),
                         "sensor_px": [W, H], "f_number": float(cam.f_number),
                         "camera_to_centre_mm": round(probe_distance_mm(cam), 9),
                         "camera_to_background_mm": float(cam.background_mm)},
              "views": views if series else {**views, "images": listed[0]}}
    if series:
        blocks["frames"] = [{"time_s": float(t), "images": images} for t, images in zip(times, listed)]
    blocks["roi_px"] = [0, 0, W, H]
    write_rig(root, blocks, first.box, first.ambient, list(heldout) if heldout is not None else [n - 1])
    return root


def write_truth(scene: Scene, path: Path) -> Path:
    """The temperature the scene was rendered from, as the shared captures hold it: ``T`` (nx, ny, nz) [K] on the
    capture's probe grid, ``sigma``, ``voxel_mm``, ``T0`` [K], ``n0``, ``delta_thre``; its ``units`` entry says
    each unit. A run scores itself against it with ``data.truth=PATH``."""
    amb = scene.ambient
    return write_npz(path, units=VOLUMES, T=scene.truth_T, sigma=amb.sigma_from_temperature(scene.truth_T),
                     voxel_mm=scene.box.voxel_mm, T0=amb.T0, n0=amb.n0, delta_thre=amb.delta_thre)


def write_calibration(cameras: list[Camera], images: list[str], references: list[str], path: Path) -> Path:
    """An OpenCV calibration file (:mod:`cv2.FileStorage` YAML, the keys :func:`read_calibration` reads) of
    ``cameras`` (each on the grid of its images), written atomically."""
    def write(tmp: str) -> None:
        fs = cv2.FileStorage(tmp, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_FORMAT_YAML)
        fs.write("n_cameras", len(cameras))
        fs.write("units", "mm")
        fs.write("world", "probe centre, y up; x, z horizontal")
        for k, (cam, image, ref) in enumerate(zip(cameras, images, references)):
            pre = f"camera_{k:02d}_"
            R = np.asarray(cam.rotation, dtype=np.float64).T  # world to camera
            fs.write(pre + "image", image)
            fs.write(pre + "reference", ref)
            fs.write(pre + "image_size", np.array([cam.width, cam.height], dtype=np.int32))
            fs.write(pre + "camera_matrix", cam.camera_matrix())
            fs.write(pre + "dist_coeffs", np.asarray(cam.distortion or (0.0,) * 5, dtype=np.float64)[None])
            fs.write(pre + "rvec", cv2.Rodrigues(R)[0])
            fs.write(pre + "tvec", (-R @ np.asarray(cam.position, dtype=np.float64))[:, None])
            fs.write(pre + "pixel_pitch_mm", float(cam.pitch_mm))
            fs.write(pre + "background_distance_mm", float(cam.background_mm))
        fs.release()

    return atomic_write(path, write)


def write_calibrated(scene: Scene, root: Path, images: list[str], heldout: Optional[list] = None) -> Path:
    """The rig file of calibrated cameras (version 3) and its calibration file, for a scene of calibrated cameras
    whose images are written (:func:`write_capture`)."""
    n, W = scene.n_views, scene.images[0].reference.shape[1]
    cams = [c.full_sensor for c in scene.cameras]
    cams = [c.binned(c.width // W) if c.width != W else c for c in cams]  # the images' grid
    refs = [f"reference_{v:02d}.png" for v in range(n)]
    write_calibration(cams, images, refs, root / "calibration.yml")
    write_rig(root, {"calibration": "calibration.yml", "f_number": float(cams[0].f_number)}, scene.box, scene.ambient,
              list(heldout) if heldout is not None else [n - 1], version=CALIBRATED_VERSION)
    return root


def target_folder(path: Path, overwrite: bool) -> Path:
    """The folder to write a new capture to (a link followed to its target, where the capture is written, so that the
    link stays), checked before anything is rendered; one sentence when it cannot take one: a file, a folder with
    something in it (unless ``overwrite``: then it is replaced whole, once the new capture is complete), the
    folder the command runs in or one holding it, or a place that cannot be written."""
    path = Path(os.path.realpath(Path(path).expanduser()))
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path} is a file: give the folder to write the capture to")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise ValueError(f"{path} is not empty: choose a new folder, or add --overwrite to replace it whole")
    here = Path.cwd().resolve()
    if path.exists() and (path == here or path in here.parents):
        raise ValueError(f"{path} is the folder this command runs in (or holds it): replacing it would remove the "
                         "folder you are in; give another folder")
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{parent} cannot be written: give a folder where you may write")
    return path


def check_space(folder: Path, rig, n_frames: int) -> None:
    """One sentence, before rendering, where the disk holding ``folder`` lacks the room for the images of a capture
    of ``n_frames`` frames through ``rig`` (the ``rig`` config; their raw size, 8-bit: PNG compresses noisy speckle
    little)."""
    images = int(rig.n_cameras) * (1 + n_frames)
    need = images * int(rig.width_px) * int(rig.height_px)
    free = shutil.disk_usage(folder).free
    if need > free:
        raise ValueError(f"the capture's {images} images need about {need / 2**20:.0f} MiB, more than the "
                         f"{free / 2**20:.0f} MiB free on the disk of {folder}: free some space or write it elsewhere")


def write(path: Path, overrides: list[str], overwrite: bool = False) -> Path:
    """Render the scene of ``overrides`` and write it as a capture to ``path``, atomically: into a sibling
    folder first, which then takes the place of ``path`` (an interrupted write leaves ``path`` as it was)."""
    path = target_folder(path, overwrite)
    fixed = ["data=synthetic", "data.sensing=realistic"]
    slip = unknown_override(fixed + list(overrides))
    if slip:
        raise ValueError(slip)
    cfg = compose(fixed + list(overrides))
    check_complete(cfg)
    check_kinds(cfg, compose(fixed + group_choices(overrides)), overrides)
    data = group(cfg, "data")
    frames = frames_of(data)
    parent = path.parent
    parent.mkdir(parents=True, exist_ok=True)
    check_space(parent, cfg.rig, len(frames) if frames is not None else 1)
    staging = path.parent / f".{path.name}.writing"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        if frames is None:
            write_capture(DATASETS.build(data, device="cpu"), staging)
        else:
            def scenes():
                for j, f in enumerate(frames):
                    log.info("frame %d of %d (t = %.4g s): rendering", j + 1, len(frames), f.time_s)
                    yield DATASETS.build(data, frame=f.index, device="cpu")

            write_capture(scenes(), staging, times=[f.time_s for f in frames])
        if path.exists():
            old = path.parent / f".{path.name}.replaced"
            shutil.rmtree(old, ignore_errors=True)
            path.rename(old)
            staging.rename(path)
            shutil.rmtree(old)
        else:
            staging.rename(path)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return path


def main(argv=None) -> Path:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("path", help="the capture folder to write (created; it must be new or empty)")
    ap.add_argument("overrides", nargs="*", help="config overrides of the synthetic scene (data.sensing is realistic)")
    ap.add_argument("--overwrite", action="store_true", help="replace a folder that holds something, whole")
    ap.add_argument("--debug", action="store_true", help="an unexpected error's traceback (else one sentence)")
    args = ap.parse_intermixed_args(argv)  # --overwrite anywhere on the line
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    try:
        root = write(Path(args.path), args.overrides, args.overwrite)
    except (ValueError, FileNotFoundError, OSError, HydraException) as e:  # one sentence, as python -m nerif
        if isinstance(e, OSError) and e.strerror:  # its words and file, not its number
            message = f"{e.filename + ': ' if e.filename else ''}{e.strerror}"
        else:
            message = str(e.args[0] if e.args else e).splitlines()[0]
        print(f"nerif.write_capture: error: {message}", file=sys.stderr, flush=True)
        sys.exit(2)
    except KeyboardInterrupt:
        print(f"nerif.write_capture: interrupted; {args.path} is as it was", file=sys.stderr, flush=True)
        sys.exit(130)
    except Exception as e:  # anything else is one sentence too (a value of the wrong kind, OpenCV's, torch's)
        if args.debug:
            raise
        print(f"nerif.write_capture: error: {unexpected(e, '--debug')}", file=sys.stderr, flush=True)
        sys.exit(2)
    rig = read_rig(root)
    views, n = rig.n_views, len(rig.frames) if len(rig.frames) > 1 else 0
    what = f"{n} frame{'s' * (n != 1)} of {views} views" if n else f"{views} views"
    truth = f" data.truth={root / TRUTH_FILE}" if n == 0 else ""
    print(f"capture of {what} written to {root} with the truth it was rendered from ({TRUTH_FILE}"
          f"{' in each frame folder' if n else ''}); reconstruct it and score it against that truth with: "
          f"python -m nerif data=capture data.root={root}{truth}")
    return root


if __name__ == "__main__":
    main()
