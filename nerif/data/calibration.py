"""An OpenCV calibration of a capture's cameras: the file (:mod:`cv2.FileStorage` YAML, keys
``camera_KK_<key>`` of :data:`CALIBRATION_KEYS` and ``n_cameras``) or a rig file's ``cameras`` list, read and
checked, and the :class:`nerif.geometry.Camera` of each entry."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from nerif.geometry import Camera

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
