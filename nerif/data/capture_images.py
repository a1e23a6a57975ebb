"""The image files of a capture: which files a frame has (each present and listed in the rig file), their headers
checked without decoding (a long series is checked before any flow runs), and greyscale images decoded once."""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from nerif.data.rig_file import RIG_FILE, RigFile, exposures

IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg"}
FULL_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
# Pillow's modes of one-channel images, as the dtype cv2.IMREAD_UNCHANGED gives them
_GREY_MODES = {"1": np.dtype(np.uint8), "L": np.dtype(np.uint8), "I;16": np.dtype(np.uint16), "I;16B": np.dtype(np.uint16),
               "I;16L": np.dtype(np.uint16), "I;16N": np.dtype(np.uint16)}


def capture_files(rig: RigFile, frame: int = 0) -> tuple[list[tuple[Path, ...]], list[tuple[Path, ...]]]:
    """The distorted and reference image of every view of ``frame``, each the tuple of its exposures' files (one
    file: a tuple of one); raises for a missing file or an image the rig file does not list (in the folder or in a
    folder of its frames)."""
    root, n = rig.root, rig.n_views
    distorted = [tuple(root / f for f in exposures(e)) for e in rig.frames[frame].images]
    references = [tuple(root / f for f in exposures(e)) for e in rig.references]
    flame = [root / f for f in rig.flame_only or ()]
    masks = {v: root / f for v, f in enumerate(rig.occluders or ()) if f is not None}
    where = f"frame {frame} " if len(rig.frames) > 1 else ""
    for k, files in enumerate(distorted + references + [(p,) for p in flame]):
        for p in files:
            if not p.is_file():
                kind = (f"{where}view {k} image" if k < n else f"view {k - n} reference" if k < 2 * n
                        else f"view {k - 2 * n} flame_only image")
                raise FileNotFoundError(f"{rig.path} lists {kind} '{p.relative_to(root)}', which does not exist "
                                        f"in {root}: add the file or remove the "
                                        f"{'frame' if where and k < n else 'view'}")
    for v, p in masks.items():
        if not p.is_file():
            raise FileNotFoundError(f"{rig.path} lists view {v}'s occluder mask '{p.relative_to(root)}', which does "
                                    f"not exist in {root}: add the file or give null for that view")
    top = root.resolve()
    listed = ({(root / f).resolve() for fr in rig.frames for e in fr.images for f in exposures(e)}
              | {p.resolve() for files in references for p in files}
              | {p.resolve() for p in flame} | {p.resolve() for p in masks.values()})
    folders = {p.parent for p in listed if top in p.parents} | {top}  # the capture's own folders, not a shared one
    extra = sorted(str(p.relative_to(top)) for d in folders for p in d.iterdir()
                   if p.suffix.lower() in IMAGE_SUFFIXES and p.resolve() not in listed)
    if extra and (top / "metrics.json").is_file():
        raise ValueError(f"{root} holds a nerif run's outputs ({', '.join(extra)} beside metrics.json), written into "
                         "the capture folder: move them out (a run's folder is hydra.run.dir)")
    if extra:
        raise ValueError(f"{root} holds image(s) {', '.join(extra)} that {RIG_FILE} does not list: add each to "
                         "views (with its angle) or to its frame, or move it out of the folder")
    return distorted, references


LOSSY_SUFFIXES = {".jpg", ".jpeg"}


def lossy_images(paths: list[Path]) -> str:
    """One sentence where some of ``paths`` are in a lossy format (JPEG), else "": its block artefacts are noise in
    the displacements (the shared clean capture saved at JPEG quality 50: sigma error 0.22 against 0.125; at 20:
    0.78)."""
    lossy = [p for p in paths if p.suffix.lower() in LOSSY_SUFFIXES]
    if not lossy:
        return ""
    return (f"{len(lossy)} of the capture's {len(paths)} images are JPEG ({lossy[0].name}, ...), a lossy format: its "
            "compression artefacts are noise in the displacements (at quality 50 the shared capture's sigma error "
            "nearly doubles); save the camera's frames as PNG or TIFF")


def occluder_masks(rig: RigFile, read) -> list:
    """(V,) each view's occluder mask (H, W) bool (True: the background is hidden) or None, from the rig file's
    ``occluders``; ``read``: a list of files -> their images (H, W) in [0, 1], as :func:`read_images`."""
    listed = [(v, rig.root / f) for v, f in enumerate(rig.occluders or ()) if f is not None]
    masks: list = [None] * rig.n_views
    if listed:
        check_images([p for _, p in listed], rig.sensor_px)
        for (v, _), img in zip(listed, read([p for _, p in listed])):
            masks[v] = img > 0
    return masks


def _colour(path: Path, channels: int) -> ValueError:
    return ValueError(f"{path} is a colour image ({channels} channels); BOS needs greyscale: convert it "
                      "(or save the camera's raw greyscale frame)")


def _checked(path: Path, shape: tuple[int, int], dtype: np.dtype, sensor_px, depth: dict) -> None:
    """One sentence where an image of ``shape`` (height, width) and ``dtype`` does not fit the capture (the
    sensor's size, 8 or 16 bit, the bit depth of the first image, kept in ``depth``)."""
    w, h = (int(x) for x in sensor_px)
    if dtype not in FULL_SCALE:
        raise ValueError(f"{path} is {dtype}; nerif reads 8-bit or 16-bit greyscale images")
    if shape != (h, w):
        if shape == (w, h):
            hint = ": sensor_px is (width, height), swap its two numbers"
        elif h % shape[0] == 0 and w % shape[1] == 0 and h // shape[0] == w // shape[1] > 1:
            k = h // shape[0]
            hint = (f": binned {k} x {k} in the camera? Then give the images' size as sensor_px and the binned pixel's "
                    f"pitch ({k} times the sensor's) as pitch_um")
        else:
            hint = ": every image must be a full frame of the same camera"
        raise ValueError(f"{path} is {shape[1]} x {shape[0]} px but the rig's sensor_px (a calibration's "
                         f"image_size) is {w} x {h}{hint}")
    first = depth.setdefault("first", (dtype, path))
    if dtype != first[0]:
        raise ValueError(f"{path} is {dtype} but {first[1].name} is {first[0]}: save every image with the same "
                         "bit depth (8 or 16 bit)")


def check_images(paths: list[Path], sensor_px) -> None:
    """Every image of ``paths`` readable, greyscale, 8 or 16 bit, of the sensor's size and of one bit depth, from
    its header alone (nothing is decoded: a long series is checked in a moment)."""
    depth: dict = {}
    for p in paths:
        try:
            with Image.open(p) as img:
                mode, (w, h), bands = img.mode, img.size, len(img.getbands())
        except (UnidentifiedImageError, OSError):
            raise ValueError(f"{p} is not a readable image") from None
        if bands > 1 or mode in ("P", "PA"):  # a palette is colour, whatever its one band says
            raise _colour(p, max(bands, 3))
        _checked(p, (h, w), _GREY_MODES.get(mode, np.dtype(np.float32) if mode == "F" else np.dtype(np.int32)),
                 sensor_px, depth)


def read_images(paths: list[Path], sensor_px) -> list[np.ndarray]:
    """Each image decoded once, as (height, width) floats in [0, 1] of its full scale; checked as
    :func:`check_images` checks them (a file that fails to decode says so)."""
    out, depth = [], {}
    for p in paths:
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{p} is not a readable image")
        if img.ndim == 3 and img.shape[2] > 1:
            raise _colour(p, img.shape[2])
        img = img.reshape(img.shape[:2])
        _checked(p, img.shape, img.dtype, sensor_px, depth)
        out.append(img.astype(np.float32) / FULL_SCALE[img.dtype])
    return out


def exposure_noise(stack: np.ndarray) -> Optional[float]:
    """The noise of the mean of K exposures (K, H, W) of one state [share of full scale]: the RMS over pixels of their
    spread about their mean (unbiased), over sqrt(K); None for one exposure (nothing to compare it with)."""
    k = len(stack)
    if k < 2:
        return None
    return float(np.sqrt(np.mean(np.var(stack, axis=0, ddof=1)) / k))


def read_exposures(views: list[tuple[Path, ...]], sensor_px) -> tuple[list[np.ndarray], list[Optional[float]]]:
    """Each view's image, the mean of its exposures (the tuple of its files), as (H, W) floats in [0, 1] of full
    scale, and that mean's noise (:func:`exposure_noise`; None for one exposure). A pixel at full scale in any
    exposure stays at full scale in the mean: what it recorded there is clipped, and the saturation step must see it.
    A view's exposures are decoded together, the views one after another."""
    images, noise = [], []
    for files in views:
        stack = np.stack(read_images(list(files), sensor_px))
        mean = stack[0]
        if len(stack) > 1:
            mean = stack.mean(0)
            mean[(stack >= 1.0).any(0)] = 1.0
        images.append(mean)
        noise.append(exposure_noise(stack))
    return images, noise
