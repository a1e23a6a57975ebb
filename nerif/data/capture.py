"""BOS captures as an experimentalist records them: a folder of background images and a rig file, ``rig.yaml``
(format versions 1-3: one camera model on an arc, a time series, or OpenCV-calibrated cameras). The format, with
every key explained, is in ``docs/captures.md``.

The pipeline per view: optical flow between distorted and reference image (``flow`` config), block means to
the processing grid (``binning``; ``auto``: about one ray per voxel across), displacement -> deflection through the
rig geometry, rays inside the ROI that cross the probe box. A pixel's ray leaves from its undistorted position;
images, flow and masks stay on the distorted pixel grid. Everything that can be wrong with the folder is checked
before the flow runs, for every frame of a time series before the first frame's flow.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Optional

import cv2
import numpy as np
import torch
import yaml

from nerif.data.frames import FRAMES, Frame, pick_frames
from nerif.data.folders import blocks_inside, dataset_folder, read_truth, region_of_interest, resolve_binning
from nerif.data.scene import DATASETS, Scene, ViewImages, heldout_views, scene_from_images
from nerif.geometry import Camera, ProbeBox, arc_rig, rays_in_box
from nerif.io.export import atomic_write, write_png
from nerif.physics import Ambient
from nerif.sensing.displacement import displacement_to_deflection
from nerif.sensing.flow import FLOW
from nerif.sensing.imaging import resample
from nerif.sensing.optics import probe_distance_mm

log = logging.getLogger(__name__)
RIG_FILE = "rig.yaml"
RIG_VERSION = 2
READ_VERSIONS = (1, 2, 3)
IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}
_DEPTHS = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}


def _need(d: dict, key: str, where: str):
    if not isinstance(d, dict) or key not in d or d[key] is None:
        raise ValueError(f"{where} lacks '{key}': see the rig file format in nerif/data/capture.py")
    return d[key]


def read_rig(root: Path) -> dict:
    """``rig.yaml`` of a capture folder, checked: format, version, required keys, view and frame lists."""
    path = root / RIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: a capture folder needs a {RIG_FILE} beside its images")
    try:
        rig = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        where = getattr(e, "problem_mark", None)
        raise ValueError(f"{path} is not valid YAML{f' (line {where.line + 1})' if where else ''}: "
                         f"{getattr(e, 'problem', None) or str(e).splitlines()[0]}") from None
    if not isinstance(rig, dict) or rig.get("format") != "nerif-capture":
        raise ValueError(f"{path} is not a nerif capture rig file (it needs 'format: nerif-capture')")
    if rig.get("version") not in READ_VERSIONS:
        raise ValueError(f"{path} has version {rig.get('version')}; this nerif reads versions "
                         f"{', '.join(str(v) for v in READ_VERSIONS[:-1])} and {READ_VERSIONS[-1]}")
    if rig["version"] == 3:
        return read_calibrated_rig(root, rig)
    cam, views = _need(rig, "camera", str(path)), _need(rig, "views", str(path))
    for k in ("focal_mm", "pitch_um", "sensor_px", "f_number", "camera_to_centre_mm", "camera_to_background_mm"):
        _need(cam, k, f"{path} camera")
    for k in ("focal_mm", "pitch_um", "f_number", "camera_to_centre_mm", "camera_to_background_mm"):
        v = cam[k]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
            raise ValueError(f"{path}: camera.{k} = {v!r} must be a positive number")
    if cam["pitch_um"] < 0.5:  # no camera has pixels under half a micrometre: a pitch in millimetres
        raise ValueError(f"{path}: camera.pitch_um = {cam['pitch_um']} is in micrometres (a pitch of "
                         f"{cam['pitch_um']} mm is {cam['pitch_um'] * 1e3:g})")
    if not cam["camera_to_background_mm"] > cam["camera_to_centre_mm"]:
        raise ValueError(f"{path}: camera.camera_to_background_mm = {cam['camera_to_background_mm']} must exceed "
                         f"camera.camera_to_centre_mm = {cam['camera_to_centre_mm']} (the background lies behind the "
                         "probe)")
    angles = _need(views, "angles_deg", f"{path} views")
    refs = _need(views, "references", f"{path} views")
    rig_frames(rig, path)
    if isinstance(refs, list) and len(refs) != len(angles):
        raise ValueError(f"{path}: views.references lists {len(refs)} files for {len(angles)} views; give one "
                         "per view or a single shared file")
    for k in ("roi_px", "probe", "ambient"):
        _need(rig, k, str(path))
    return rig


CALIBRATION_KEYS = ("image", "reference", "image_size", "camera_matrix", "dist_coeffs", "rvec", "tvec",
                    "pixel_pitch_mm", "background_distance_mm")


def calibration_entry(values: dict, name: str, where: str) -> dict:
    """One camera of a calibration (``values``: :data:`CALIBRATION_KEYS` -> value, None where absent), checked:
    ``name``, ``image``, ``reference``, ``size`` (w, h), ``K`` (3, 3), ``dist`` (5,), ``rvec``, ``tvec`` (3,),
    ``pitch_mm``, ``background_mm``; one sentence naming ``where`` (the camera) and the key otherwise."""
    def numbers(key: str, n: int) -> np.ndarray:
        v = values.get(key)
        try:
            a = np.asarray(v, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if v is None or a.size != n or not np.all(np.isfinite(a)):
            raise ValueError(f"{where}: '{key}' must be {n} finite numbers")
        return a

    c = {"name": name}
    for key in ("image", "reference"):
        if not isinstance(values.get(key), str) or not values[key]:
            raise ValueError(f"{where} lacks '{key}' (a file name)")
        c[key] = values[key]
    K = numbers("camera_matrix", 9).reshape(3, 3)
    if not (K[0, 0] > 0 and K[1, 1] > 0) or abs(K[0, 1]) > 1e-9 * K[0, 0] or not np.allclose(K[2], [0, 0, 1]):
        raise ValueError(f"{where}: 'camera_matrix' must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
    try:
        dist = np.asarray(values["dist_coeffs"] if values.get("dist_coeffs") is not None else np.zeros(5),
                          dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        dist = np.zeros(0)
    if dist.size not in (4, 5) or not np.all(np.isfinite(dist)):
        raise ValueError(f"{where}: 'dist_coeffs' must be (k1, k2, p1, p2[, k3]), finite")
    for key in ("pixel_pitch_mm", "background_distance_mm"):
        v = values.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
            raise ValueError(f"{where}: '{key}' must be a positive length [mm]")
        c[key] = float(v)
    c.update(size=tuple(int(x) for x in numbers("image_size", 2)), K=K, dist=np.pad(dist, (0, 5 - dist.size)),
             rvec=numbers("rvec", 3), tvec=numbers("tvec", 3))
    return c


def read_calibration(path: Path) -> list[dict]:
    """Every camera of an OpenCV calibration file (:mod:`cv2.FileStorage` YAML, keys ``camera_KK_<key>`` of
    :data:`CALIBRATION_KEYS` and ``n_cameras``), as :func:`calibration_entry` gives them."""
    if not path.is_file():
        raise FileNotFoundError(f"{path} (rig.yaml's calibration) does not exist")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as e:
        raise ValueError(f"{path} is not a calibration file cv2.FileStorage reads: {str(e).splitlines()[-1]}") from None
    if not fs.isOpened():
        raise ValueError(f"{path} is not a calibration file cv2.FileStorage reads")
    n = fs.getNode("n_cameras")
    if n.empty() or not n.real() >= 1:
        raise ValueError(f"{path} lacks 'n_cameras' (a number of at least 1)")

    def value(node):
        if node.empty():
            return None
        if node.isString():
            return node.string()
        if node.isReal() or node.isInt():
            return node.real()
        return node.mat()

    cams = []
    for k in range(int(n.real())):
        pre = f"camera_{k:02d}_"
        values = {key: value(fs.getNode(pre + key)) for key in CALIBRATION_KEYS}
        cams.append(calibration_entry(values, f"camera {k:02d}", f"{path}: camera {k:02d} ({pre}<key>)"))
    fs.release()
    return cams


def calibrated_camera(c: dict, f_number: float) -> Camera:
    """The camera of one entry of :func:`read_calibration` (full sensor): pose from ``rvec``, ``tvec``,
    intrinsics and distortion from ``K``, ``dist``; the lens focal length follows from the image distance and the
    background distance (thin lens, in focus on the background)."""
    R, _ = cv2.Rodrigues(c["rvec"])  # world to camera
    K, pitch, bg = c["K"], c["pixel_pitch_mm"], c["background_distance_mm"]
    s_i = K[0, 0] * pitch
    return Camera(-R.T @ c["tvec"], R.T, s_i, pitch, c["size"][0], c["size"][1], float(f_number), bg,
                  1.0 / (1.0 / s_i + 1.0 / bg), name=c["name"], centre_px=(K[0, 2] + 0.5, K[1, 2] + 0.5),
                  aspect=K[1, 1] / K[0, 0], distortion=tuple(float(x) for x in c["dist"]))


def read_calibrated_rig(root: Path, rig: dict) -> dict:
    """A version-3 rig file: its cameras from the calibration file it names, in the form of the other versions
    (``camera.sensor_px``, ``views``) plus ``calibrated`` (the cameras)."""
    path = root / RIG_FILE
    if ("calibration" in rig) == ("cameras" in rig):
        raise ValueError(f"{path}: version 3 needs either 'calibration' (an OpenCV calibration file) or a 'cameras' "
                         f"list, {'not both' if 'cameras' in rig else 'one of them'}")
    if "cameras" in rig:
        if not isinstance(rig["cameras"], list) or not rig["cameras"]:
            raise ValueError(f"{path}: 'cameras' must be a list with one entry per camera")
        cal = [calibration_entry(c if isinstance(c, dict) else {}, f"camera {k:02d}", f"{path}: cameras[{k}]")
               for k, c in enumerate(rig["cameras"])]
    else:
        cal = read_calibration(root / str(rig["calibration"]))
    sizes = {c["size"] for c in cal}
    if len(sizes) > 1:
        raise ValueError(f"{path}: the cameras' image sizes differ ({sorted(sizes)}); nerif needs "
                         "one size for all")
    w, h = next(iter(sizes))
    cameras = [calibrated_camera(c, float(rig.get("f_number", 32.0))) for c in cal]
    if len({c["name"] for c in cal}) != len(cal):
        raise ValueError(f"{path}: two cameras share a name")
    angles = [round(float(np.degrees(np.arctan2(c.position[0], c.position[2]))), 6) for c in cameras]
    for k in ("probe", "ambient"):
        _need(rig, k, str(path))
    return {**rig, "camera": {"sensor_px": [w, h]}, "roi_px": rig.get("roi_px", [0, 0, w, h]),
            "views": {"angles_deg": angles, "images": [c["image"] for c in cal],
                      "references": [c["reference"] for c in cal]}, "calibrated": cameras}


def rig_frames(rig: dict, path: Path = Path(RIG_FILE)) -> list[dict]:
    """The frames of a rig file, each ``{"time_s", "images"}`` with one image per view: its ``frames`` list
    (version 2), or its ``views.images`` as one frame at time 0; checked."""
    views, n = rig["views"], len(rig["views"]["angles_deg"])
    if rig.get("version") == 1 and "frames" in rig:
        raise ValueError(f"{path}: a frames list (a time series) needs 'version: 2'")
    if ("frames" in rig) == ("images" in views):
        raise ValueError(f"{path}: give the images either as views.images (one steady state) or as a frames list "
                         f"(a time series, version 2), {'not both' if 'frames' in rig else 'one of them'}")
    if "images" in views:
        images = _need(views, "images", f"{path} views")
        if len(images) != n:
            raise ValueError(f"{path}: views.angles_deg has {n} angles but views.images lists {len(images)} "
                             "images; give one angle per image")
        return [{"time_s": 0.0, "images": images}]
    frames = rig["frames"]
    if not isinstance(frames, list) or not frames:
        raise ValueError(f"{path}: frames must be a list of frames, each with its time_s and images")
    for k, fr in enumerate(frames):
        images = _need(fr, "images", f"{path} frame {k}")
        _need(fr, "time_s", f"{path} frame {k}")
        if not isinstance(images, list) or len(images) != n:
            got = len(images) if isinstance(images, list) else "no list of"
            raise ValueError(f"{path}: frame {k} lists {got} images for {n} views (views.angles_deg): every frame "
                             "needs one image per view, in the order of the angles")
        if k and not float(fr["time_s"]) > float(frames[k - 1]["time_s"]):
            raise ValueError(f"{path}: frame {k} has time_s {fr['time_s']}, not after frame {k - 1}'s "
                             f"{frames[k - 1]['time_s']}: list the frames in time order")
    return [{"time_s": float(fr["time_s"]), "images": fr["images"]} for fr in frames]


def read_grey(path: Path) -> np.ndarray:
    """A greyscale 8- or 16-bit image as stored (raises for colour, other depths, unreadable files)."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path} is not a readable image")
    if img.ndim == 3 and img.shape[2] > 1:
        raise ValueError(f"{path} is a colour image ({img.shape[2]} channels); BOS needs greyscale: convert it "
                         "(or save the camera's raw greyscale frame)")
    img = img.reshape(img.shape[:2])
    if img.dtype not in _DEPTHS:
        raise ValueError(f"{path} is {img.dtype}; nerif reads 8-bit or 16-bit greyscale images")
    return img


def capture_files(root: Path, rig: dict, frame: int = 0) -> tuple[list[Path], list[Path]]:
    """The distorted and reference image of every view of ``frame``; raises for a missing file or an image the
    rig file does not list (in the folder or in a folder of its frames)."""
    views, frames = rig["views"], rig_frames(rig)
    n = len(views["angles_deg"])
    refs = views["references"] if isinstance(views["references"], list) else [views["references"]] * n
    distorted, references = [root / f for f in frames[frame]["images"]], [root / f for f in refs]
    where = f"frame {frame} " if len(frames) > 1 else ""
    for k, p in enumerate(distorted + references):
        if not p.is_file():
            kind = f"{where}view {k} image" if k < n else f"view {k - n} reference"
            raise FileNotFoundError(f"{root / RIG_FILE} lists {kind} '{p.relative_to(root)}', which does not exist "
                                    f"in {root}: add the file or remove the {'frame' if where and k < n else 'view'}")
    top = root.resolve()
    listed = {(root / f).resolve() for fr in frames for f in fr["images"]} | {p.resolve() for p in references}
    folders = {p.parent for p in listed if top in p.parents} | {top}  # the capture's own folders, not a shared one
    extra = sorted(str(p.relative_to(top)) for d in folders for p in d.iterdir()
                   if p.suffix.lower() in IMAGE_SUFFIXES and p.resolve() not in listed)
    if extra:
        raise ValueError(f"{root} holds image(s) {', '.join(extra)} that {RIG_FILE} does not list: add each to "
                         "views (with its angle) or to its frame, or move it out of the folder")
    return distorted, references


def read_images(paths: list[Path], sensor_px, keep: bool = True) -> list[np.ndarray]:
    """Images as floats in [0, 1]; all of one bit depth and of the rig's sensor size (``keep=False``: only
    checked, one at a time, and none returned: a long series is checked without holding it in memory)."""
    w, h = (int(x) for x in sensor_px)
    out, depth = [], None
    for p in paths:
        img = read_grey(p)
        if img.shape != (h, w):
            raise ValueError(f"{p} is {img.shape[1]} x {img.shape[0]} px but the rig's sensor_px (a calibration's "
                             f"image_size) is {w} x {h}: every image must be a full frame of the same camera")
        if depth is None:
            depth = (img.dtype, p)
        elif img.dtype != depth[0]:
            raise ValueError(f"{p} is {img.dtype} but {depth[1].name} is {depth[0]}: save every image with the same "
                             "bit depth (8 or 16 bit)")
        if keep:
            out.append(img.astype(np.float32) / _DEPTHS[img.dtype])
    return out


def rig_cameras(rig: dict, binning=1, box: Optional[ProbeBox] = None):
    """The rig's cameras (full sensor) from its file, and the same read out with ``binning`` (``auto``: about one
    ray per voxel of ``box`` across, :func:`nerif.geometry.ray_binning`)."""
    c = rig["camera"]
    w, h = (int(x) for x in c["sensor_px"])
    if "calibrated" in rig:
        full = rig["calibrated"]
    else:
        full = arc_rig(angles_deg=[float(a) for a in rig["views"]["angles_deg"]],
                       distance_mm=float(c["camera_to_centre_mm"]), focal_mm=float(c["focal_mm"]), width_px=w,
                       height_px=h, pitch_um=float(c["pitch_um"]),
                       background_behind_mm=float(c["camera_to_background_mm"]) - float(c["camera_to_centre_mm"]),
                       f_number=float(c["f_number"]), binning=1)
    binning = resolve_binning(binning, full, box, f"the sensor size {w} x {h} px")
    return full, [cam.binned(binning) if binning > 1 else cam for cam in full]


def roi_mask(rig: dict, root: Path, binning: int) -> np.ndarray:
    """(h, w) bool on the processing grid: blocks wholly inside the region of interest."""
    w, h = (int(x) for x in rig["camera"]["sensor_px"])
    x, y, dw, dh = (int(v) for v in rig["roi_px"])
    roi = region_of_interest(x, y, dw, dh, w, h, f"{root / RIG_FILE}: roi_px {rig['roi_px']} (x, y, width, height)")
    return blocks_inside(roi, h // binning, w // binning)


def sigma_prior(rig: dict, ambient: Ambient, root: Path) -> Optional[tuple]:
    """The field's interval from the rig's ``temperature_range_K`` (with ambient, sigma = 0, inside it and a 0.05
    margin), or None."""
    if rig.get("temperature_range_K") is None:
        return None
    lo, hi = (float(t) for t in rig["temperature_range_K"])
    if not 0 < lo < hi:
        raise ValueError(f"{root / RIG_FILE}: temperature_range_K {rig['temperature_range_K']} must be two "
                         "increasing positive temperatures [K]")
    s_hot, s_cold = ambient.sigma_from_temperature(hi), ambient.sigma_from_temperature(lo)
    return min(s_hot, 0.0) - 0.05, max(s_cold, 0.0) + 0.05


@FRAMES.register("capture")
def capture_frames(root: str, frames=None, **_) -> Optional[list[Frame]]:
    """``data.frames`` of a capture folder: None for a folder of one frame (unless frames are asked for), else
    every frame (null) or those picked; every picked frame's files are checked (present, listed, readable, of
    the sensor's size and one bit depth) before any flow runs."""
    root = dataset_folder(root)
    rig = read_rig(root)
    listed = rig_frames(rig, root / RIG_FILE)
    if frames is None and len(listed) == 1:
        return None
    picked = pick_frames(frames, len(listed))
    distorted, references = [], []
    for k in picked:
        d, references = capture_files(root, rig, k)
        distorted += d
    read_images(distorted + references, rig["camera"]["sensor_px"], keep=False)
    return [Frame(k, listed[k]["time_s"]) for k in picked]


def _optional(rig: dict, key: str, default):
    """An optional key of ``rig.yaml``: its value, or ``default`` where it is absent or null."""
    value = rig.get(key)
    return default if value is None else value


@DATASETS.register("capture")
def capture(root: str, flow: dict, binning="auto", heldout: Optional[list] = None, frames=None,
            frame: Optional[int] = None, truth: Optional[str] = None, device: str = "cpu") -> Scene:
    """A capture folder -> scene of the training views, with the held-out views as ``scene.heldout``.

    Args:
        root: the capture folder. flow: a :data:`nerif.sensing.flow.FLOW` config.
        binning: b x b sensor pixels averaged into one ray (the processing grid); ``auto``: about one ray per
            voxel across at the probe (:func:`nerif.geometry.ray_binning`), logged.
        heldout: views never trained on (overrides the rig file's ``heldout``; default: the last view).
        frames: the frames of a time series (:func:`capture_frames`); ``frame``: the one to build (None: the
            first of the folder).
        truth: a volume file of the true temperature [K] on the probe grid, for a rendered capture (its array
            ``T``): every error against the truth is then reported. None for a real experiment.
    """
    root = dataset_folder(root)
    rig = read_rig(root)
    FLOW.get(flow["name"])
    frame = 0 if frame is None else int(frame)
    if not 0 <= frame < len(rig_frames(rig)):
        raise ValueError(f"frame {frame}: {root / RIG_FILE} lists {len(rig_frames(rig))} frame(s)")
    distorted, references = capture_files(root, rig, frame)
    box = ProbeBox(tuple(int(n) for n in _need(rig["probe"], "shape", "rig probe")),
                   float(_need(rig["probe"], "voxel_mm", "rig probe")))
    full, cameras = rig_cameras(rig, binning, box)
    valid = roi_mask(rig, root, cameras[0].binning)
    amb = rig["ambient"]
    ambient = Ambient(float(_need(amb, "T0", "rig ambient")), float(_need(amb, "n0", "rig ambient")),
                      float(_optional(rig, "T_max", 2000.0)))
    held = heldout_views(heldout if heldout is not None else _optional(rig, "heldout", [len(cameras) - 1]),
                         len(cameras))
    prior = sigma_prior(rig, ambient, root)
    truth_T = read_truth(truth, box) if truth is not None else None
    rays = rays_in_box(box, cameras, device)  # a camera that does not see the box fails here, before the flow
    pixel, starts = rays[2].cpu(), rays[3].cpu()
    for v, cam in enumerate(cameras):
        if not valid.reshape(-1)[pixel[starts[v]:starts[v + 1]].numpy()].any():
            raise ValueError(f"{cam.name}: no pixel of roi_px {rig['roi_px']} sees the probe box "
                             f"{box.extent_mm.tolist()} mm ({root / RIG_FILE}): check the region of interest, the "
                             "distances and the probe box")
    both = read_images(distorted + references, rig["camera"]["sensor_px"])  # one bit depth for all
    images, refs = both[:len(distorted)], both[len(distorted):]

    eps_images = []
    for v, (cam, cam_full) in enumerate(zip(cameras, full)):
        u = FLOW.build(flow, distorted=images[v], reference=refs[v])
        u = resample(u, cam.height, cam.width)
        d = cam.pixel_directions(torch.float64)
        eps = displacement_to_deflection(torch.as_tensor(u.reshape(-1, 2), dtype=torch.float64), d, cam_full)
        eps_images.append(eps.numpy().reshape(cam.height, cam.width, 3))
        log.info("%s: displacement up to %.2f px", cam.name, float(np.nanmax(np.linalg.norm(u, axis=-1))))

    views = [ViewImages(torch.as_tensor(r, device=device), torch.as_tensor(i, device=device), cam)
             for r, i, cam in zip(refs, images, full)]
    scene = scene_from_images(box, ambient, cameras, eps_images, [valid] * len(cameras), device=device, rays=rays,
                              sigma_prior=prior, images=views, truth_T=truth_T)
    return scene.split_views(held)


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
        if scene.sensing is None or "distorted" not in scene.sensing:
            raise ValueError("writing a capture needs images: use data.sensing=realistic")
        dist = scene.sensing["distorted"]
        folder = f"frame_{k:04d}/" if series else ""
        listed.append([f"{folder}distorted_{v:02d}.png" for v in range(len(dist))])
        for v, name in enumerate(listed[-1]):
            write_png(root / name, dist[v])
        if first is None:
            first = scene
            for v, ref in enumerate(scene.sensing["reference"]):
                write_png(root / f"reference_{v:02d}.png", ref)
    if first is None or (series and len(listed) != len(times)) or (not series and len(listed) != 1):
        raise ValueError(f"{len(listed)} scene(s) for {len(times) if series else 1} frame(s)")
    n, H, W = first.sensing["distorted"].shape
    if any(c.distortion is not None or c.centre_px is not None or c.aspect != 1.0 for c in first.cameras):
        if series:
            raise ValueError("a time series through a calibrated rig is not written yet: write one state at a time")
        return write_calibrated(first, root, listed[0], heldout)
    cam = first.cameras[0].unbinned(first.cameras[0].binning)  # the full sensor
    angles = [round(float(np.degrees(np.arctan2(c.position[0], c.position[2]))), 6) for c in first.cameras]
    views = {"angles_deg": angles, "references": [f"reference_{v:02d}.png" for v in range(n)]}
    rig = {"format": "nerif-capture", "version": RIG_VERSION,
           "camera": {"focal_mm": float(cam.focal_mm), "pitch_um": round(cam.pitch_mm * 1e3 * cam.width / W, 9),
                      "sensor_px": [W, H], "f_number": float(cam.f_number),
                      "camera_to_centre_mm": round(probe_distance_mm(cam), 9),
                      "camera_to_background_mm": float(cam.background_mm)},
           "views": views if series else {**views, "images": listed[0]}}
    if series:
        rig["frames"] = [{"time_s": float(t), "images": images} for t, images in zip(times, listed)]
    rig.update({"roi_px": [0, 0, W, H],
                "probe": {"shape": [int(s) for s in first.box.shape], "voxel_mm": float(first.box.voxel_mm)},
                "ambient": {"T0": float(first.ambient.T0), "n0": float(first.ambient.n0)},
                "T_max": float(first.ambient.T_max),
                "temperature_range_K": [float(first.ambient.T0), float(first.ambient.T_max)],
                "heldout": list(heldout) if heldout is not None else [n - 1]})
    atomic_write(root / RIG_FILE, lambda t: Path(t).write_text(
        "# nerif capture rig file (format: nerif/data/capture.py); written from a synthetic scene\n"
        + yaml.safe_dump(rig, sort_keys=False, default_flow_style=None)))
    return root


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
    """The rig file of version 3 and its calibration file, for a scene of calibrated cameras whose images are
    written (:func:`write_capture`)."""
    n, H, W = scene.sensing["distorted"].shape
    cams = [c.unbinned(c.binning) for c in scene.cameras]
    cams = [c.binned(c.width // W) if c.width != W else c for c in cams]  # the images' grid
    refs = [f"reference_{v:02d}.png" for v in range(n)]
    write_calibration(cams, images, refs, root / "calibration.yml")
    rig = {"format": "nerif-capture", "version": 3, "calibration": "calibration.yml",
           "probe": {"shape": [int(s) for s in scene.box.shape], "voxel_mm": float(scene.box.voxel_mm)},
           "ambient": {"T0": float(scene.ambient.T0), "n0": float(scene.ambient.n0)},
           "T_max": float(scene.ambient.T_max), "f_number": float(cams[0].f_number),
           "temperature_range_K": [float(scene.ambient.T0), float(scene.ambient.T_max)],
           "heldout": list(heldout) if heldout is not None else [n - 1]}
    atomic_write(root / RIG_FILE, lambda t: Path(t).write_text(
        "# nerif capture rig file, version 3 (format: nerif/data/capture.py); written from a synthetic scene\n"
        + yaml.safe_dump(rig, sort_keys=False, default_flow_style=None)))
    return root
