"""The BOS paper's dataset format: ``transforms_{train,val,test}.json`` with per-view deflection images.

Format (as in the authors' Phantom 1 data, ``../shared/data/nirbos_phantom1/README.md``):

- intrinsics ``fl_x``, ``cx``, ``cy``, ``w``, ``h`` [px]; ``image_min``, ``image_max``: the deflection range the
  16-bit images span; per frame ``transform_matrix`` (camera-to-world, OpenGL axes, lengths in units of the
  pixel pitch; see :func:`nerif.geometry.camera_from_nerf_pose`), ``file_path`` (a 16-bit 3-channel PNG, BGR
  on disk, RGB = world-frame eps_x, eps_y, eps_z: ``value = png / 65535 * (max - min) + min``),
  ``mask_file_path`` (2-D mask PNG) and ``UVROI`` = ``[u, v, w, h]``, 1-based.
- paths may be spelled with Windows backslashes.
- the deflections are those of sigma (dimensionless), so the scene's ``T_max`` is unknown and it stays in
  sigma units; the probe box and ambient state are not in the files and come from the config.

The stored vectors are perpendicular to each camera's axis, not to each ray; the physical deflection with the
same background displacement is their projection perpendicular to the ray (``eps - d (eps . d)``), which is
what the scene keeps (:func:`nerif.data.scene.scene_from_images`).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import cv2
import numpy as np

from nerif.data.folders import blocks_inside, dataset_folder, read_truth, region_of_interest, resolve_binning
from nerif.data.scene import DATASETS, Scene, scene_from_images
from nerif.geometry import Camera, ProbeBox, camera_from_nerf_pose
from nerif.export import atomic_write, write_png
from nerif.physics import Ambient
from nerif.sensing.imaging import resample

_KEYS = ("fl_x", "cx", "cy", "w", "h", "image_min", "image_max", "frames")


def _path(root: Path, spelled: str, what: str) -> Path:
    p = root / spelled.replace("\\", "/")
    if not p.is_file():
        raise FileNotFoundError(f"{what}: {p} does not exist (check the dataset folder)")
    return p


def read_png(path: Path, channels: int, depth=np.uint16) -> np.ndarray:
    """A PNG exactly as stored, checked for bit depth and channel count: (H, W) or (H, W, C)."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path} is not a readable image")
    have = 1 if img.ndim == 2 else img.shape[2]
    if img.dtype != depth or have != channels:
        raise ValueError(f"{path} is {img.dtype} with {have} channel(s); expected {np.dtype(depth).name} with "
                         f"{channels}")
    return img


def read_split(root: Path, split: str) -> dict:
    """The parsed ``transforms_<split>.json``, checked for the keys the importer needs."""
    path = root / f"transforms_{split}.json"
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: data.root must be a folder with transforms_{split}.json")
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path} is not valid JSON (line {e.lineno}): {e.msg}") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path} holds no JSON object of keys")
    missing = [k for k in _KEYS if k not in meta]
    if missing:
        raise ValueError(f"{path} lacks {', '.join(missing)}")
    if not isinstance(meta["frames"], list):
        raise ValueError(f"{path}: frames must be a list (one entry per view), not a {type(meta['frames']).__name__}")
    if not meta["frames"]:
        raise ValueError(f"{path} has no frames")
    for k, fr in enumerate(meta["frames"]):
        lacks = [key for key in ("file_path", "mask_file_path", "transform_matrix")
                 if not isinstance(fr, dict) or key not in fr]
        if lacks:
            raise ValueError(f"{path}: frame {k} lacks {', '.join(lacks)}")
    try:
        lo, hi = float(meta["image_min"]), float(meta["image_max"])
    except (TypeError, ValueError):
        lo = hi = float("nan")
    if not hi > lo:  # equal: every pixel would decode to one constant deflection
        raise ValueError(f"{path}: image_max ({meta['image_max']}) must exceed image_min ({meta['image_min']}), "
                         "the deflection range the 16-bit images span")
    return meta


def read_frame(root: Path, split: str, meta: dict, k: int, optics: dict):
    """Frame ``k`` of a split at full resolution: its camera, its deflections (H, W, 3) as stored (world frame,
    the json's units), its region of interest (H, W) bool and its 2-D mask (H, W) bool."""
    w, h = int(meta["w"]), int(meta["h"])
    lo, hi = float(meta["image_min"]), float(meta["image_max"])
    fr = meta["frames"][k]
    name = f"{split} view {k} ({fr['file_path']})"
    img = read_png(_path(root, fr["file_path"], name), 3)
    mask = read_png(_path(root, fr["mask_file_path"], name), 3)
    if img.shape[:2] != (h, w) or mask.shape[:2] != (h, w):
        raise ValueError(f"{name}: images are {img.shape[1]} x {img.shape[0]} px, the json's w and h say {w} x {h}")
    cam = camera_from_nerf_pose(fr["transform_matrix"], float(meta["fl_x"]), w, h, float(meta["cx"]),
                                float(meta["cy"]), name=name, **optics)
    eps = cv2.cvtColor(img, cv2.COLOR_BGR2RGB).astype(np.float64) / 65535.0 * (hi - lo) + lo
    u, v, du, dv = (int(x) for x in fr.get("UVROI", [1, 1, w, h]))  # 1-based
    roi = region_of_interest(u - 1, v - 1, du, dv, w, h, f"{name}: UVROI {fr.get('UVROI')} (1-based u, v, w, h)")
    return cam, eps, roi, mask[..., 0] > 0


def load_views(root: Path, split: str, box: ProbeBox, ambient: Ambient, optics: dict, binning=1,
               device="cpu", **fields) -> Scene:
    """The views of one split as a scene (deflections in sigma units, the split's own 2-D masks and ROI), read out
    with ``binning`` (``auto``: :func:`nerif.data.folders.resolve_binning`)."""
    meta = read_split(root, split)
    frames = [read_frame(root, split, meta, k, optics) for k in range(len(meta["frames"]))]  # checks w, h first
    binning = resolve_binning(binning, [f[0] for f in frames], box, f"the image size {meta['w']} x {meta['h']} px")
    cameras, eps_images, valid, masks = [], [], [], []
    for cam, eps, roi, mask in frames:
        cam = cam.binned(binning) if binning > 1 else cam
        cameras.append(cam)
        eps_images.append(resample(eps * ambient.delta_thre, cam.height, cam.width))  # block means
        valid.append(blocks_inside(roi, cam.height, cam.width))
        masks.append(resample(mask.astype(np.float32), cam.height, cam.width) > 0)
    return scene_from_images(box, ambient, cameras, eps_images, valid, device=device, masks=masks, **fields)


def optics(pitch_um: float = 20.0, focal_mm: float = 105.0, f_number: float = 32.0,
           background_mm: float = 1600.0) -> dict:
    """Camera parameters the files do not hold, for :func:`camera_from_nerf_pose` (poses in pixel pitches)."""
    return dict(pitch_mm=pitch_um * 1e-3, length_mm=pitch_um * 1e-3, f_number=f_number,
                background_mm=background_mm, focal_mm=focal_mm)


@DATASETS.register("transforms")
def transforms(root: str, probe: dict, T0: float, n0: float, *, sigma_prior: Optional[list],
               T_max: Optional[float] = None, heldout_split: Optional[str] = "val", heldout_views: Optional[list] = None,
               binning="auto", pitch_um: float = 20.0, focal_mm: float = 105.0, f_number: float = 32.0,
               background_mm: float = 1600.0, truth: Optional[str] = None, device: str = "cpu") -> Scene:
    """Train on ``transforms_train.json``; hold out ``transforms_<heldout_split>.json`` (None: no held-out views),
    or, with ``heldout_views``, those views of the training split (novel views; ``heldout_split`` must be None).

    Args:
        root: the dataset folder. probe: ``shape`` (nx, ny, nz) and ``voxel_mm`` of the reconstruction grid,
            centred on the world origin. T0, n0: ambient state. T_max: None (the files hold deflections of sigma).
        binning: b x b pixel blocks averaged into one ray (1 = every pixel); ``auto``: about one ray per voxel
            across at the probe (:func:`nerif.geometry.ray_binning`).
        sigma_prior: (a, b) interval of sigma the dataset's flame lies in (the field's prior unless ``field.prior``
            is set); None: the field's default.
        pitch_um: pixel pitch, also the length unit of the poses. focal_mm, f_number, background_mm: lens and
            camera-to-background distance (not in the files; used only for displacements and figures).
        truth: a volume file (.npy, .npz, .mat, .h5) of the true temperature [K] on the probe grid, when known
            (a rendered dataset): every error against the truth is then reported; needs ``T_max``.
    """
    root = dataset_folder(root)
    box = ProbeBox(tuple(int(n) for n in probe["shape"]), float(probe["voxel_mm"]))
    ambient = Ambient(float(T0), float(n0), None if T_max is None else float(T_max))
    truth_T = None
    if truth is not None:
        if T_max is None:
            raise ValueError("data.truth is a temperature volume: set data.T_max (the temperature of sigma = -1 "
                             "the dataset was rendered with) to compare against it")
        truth_T = read_truth(truth, box)
    cams = optics(pitch_um, focal_mm, f_number, background_mm)
    scene = load_views(root, "train", box, ambient, cams, binning, device, truth_T=truth_T,
                       sigma_prior=tuple(float(x) for x in sigma_prior) if sigma_prior is not None else None,
                       sigma_prior_from="data.sigma_prior")
    if heldout_views is not None:
        if heldout_split:
            raise ValueError("data.heldout_views holds out training views: set data.heldout_split=null with it")
        return scene.split_views(heldout_views)
    if heldout_split:
        scene.heldout = load_views(root, heldout_split, box, ambient, cams, scene.cameras[0].binning, device)
    return scene


def write_split(root: Path, split: str, cameras: list[Camera], eps_images: list[np.ndarray],
                mask_images: list[np.ndarray], image_range: Optional[tuple] = None) -> Path:
    """Write views in the paper's format: ``transforms_<split>.json``, a 16-bit deflection PNG and a mask PNG per
    view (``<split>/<k>.png``, ``<split>/<k>_mask.png``), poses in units of the cameras' pixel pitch (read them
    back with ``data.pitch_um`` = that pitch).

    Args:
        cameras: V cameras of one size, principal point at the sensor centre.
        eps_images: per view (H, W, 3) world-frame deflections of sigma. mask_images: per view (H, W) bool.
        image_range: (min, max) the 16-bit images span; None: the views' own range.
    """
    root = Path(root)
    lo, hi = image_range if image_range is not None else (min(float(e.min()) for e in eps_images),
                                                          max(float(e.max()) for e in eps_images))
    cam0 = cameras[0]
    frames = []
    for k, (cam, eps, mask) in enumerate(zip(cameras, eps_images, mask_images)):
        png = np.round((np.clip(eps, lo, hi) - lo) / (hi - lo) * 65535.0).astype(np.uint16)
        write_png(root / split / f"{k}.png", cv2.cvtColor(png, cv2.COLOR_RGB2BGR))
        write_png(root / split / f"{k}_mask.png", np.repeat(mask[..., None].astype(np.uint16) * 65535, 3, -1))
        c2w = np.eye(4)
        c2w[:3, :3] = np.asarray(cam.rotation) @ np.diag([1.0, -1.0, -1.0])  # (right, down, forward) -> OpenGL
        c2w[:3, 3] = np.asarray(cam.position) / cam.pitch_mm
        frames.append({"file_path": f"{split}/{k}.png", "mask_file_path": f"{split}/{k}_mask.png",
                       "transform_matrix": c2w.tolist(), "UVROI": [1, 1, cam.width, cam.height]})
    meta = {"fl_x": cam0.image_distance_mm / cam0.pitch_mm, "cx": cam0.width / 2, "cy": cam0.height / 2,
            "w": cam0.width, "h": cam0.height, "image_min": lo, "image_max": hi, "frames": frames}
    path = root / f"transforms_{split}.json"
    atomic_write(path, lambda t: Path(t).write_text(json.dumps(meta, indent=1)))
    return path


def reference_mask3d(root: str, box: ProbeBox, bound: float = 2.0, scale: float = 0.00054421,
                     pitch_um: float = 20.0) -> np.ndarray:
    """The authors' ``3Dmask.mat`` (``maskback``, indexed [x, y, z] over the cube [-bound, bound]^3 of their
    units, nodes at both ends, ``scale`` units per pixel pitch) sampled at the centres of ``box``, as they
    sample it (nearest lower node). Returns (nx, ny, nz) bool."""
    from scipy.io import loadmat

    path = Path(root).expanduser() / "3Dmask.mat"
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist")
    m = loadmat(str(path))["maskback"] > 0
    units = box.centres() / (pitch_um * 1e-3) * scale  # mm -> their units
    idx = np.clip(((units + bound) / (2 * bound) * (np.asarray(m.shape) - 1)).astype(np.int64), 0,
                  np.asarray(m.shape) - 1)
    return m[idx[..., 0], idx[..., 1], idx[..., 2]]
