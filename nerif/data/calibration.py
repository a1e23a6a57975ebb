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
# What cameras have: (least, most, what a value outside says, as a function of it). Outside these a value is in
# another unit (a focal length in metres, a pitch in nanometres), not a camera nerif would be wrong to refuse.
FOCAL_MM = (1.0, 5000.0, lambda v: f"a focal length in metres? {v} m is {v * 1e3:g} mm" if v < 1
            else f"a focal length in micrometres? {v} um is {v * 1e-3:g} mm")
PITCH_UM = (0.5, 100.0, lambda v: f"a pitch in millimetres? {v} mm is {v * 1e3:g} um" if v < 0.5
            else f"a pitch in nanometres? {v} nm is {v * 1e-3:g} um")
DISTANCE_MM = (10.0, 1.0e5, lambda v: f"a distance in metres? {v} m is {v * 1e3:g} mm" if v < 10
               else f"a distance in micrometres? {v} um is {v * 1e-3:g} mm")
F_NUMBER = (0.5, 256.0, lambda v: "f-numbers run from about 1 to 64 (the focal length over the aperture's diameter)")
MAX_DISTORTION = 0.25  # the most a lens's distortion moves an image's corner (a share of its distance from the centre)


def plausible(value: float, limits: tuple, what: str) -> float:
    """``value`` where it is within ``limits`` (least, most, the hint), else one sentence naming ``what``."""
    lo, hi, hint = limits
    if not lo <= value <= hi:
        raise ValueError(f"{what} = {value:g} is outside what cameras have ({lo:g} to {hi:g}): {hint(value)}")
    return value


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
    plausible(c["pixel_pitch_mm"] * 1e3, PITCH_UM, f"{where}: 'pixel_pitch_mm' x 1000 [um]")
    plausible(c["background_distance_mm"], DISTANCE_MM, f"{where}: 'background_distance_mm'")
    plausible(float(K[0, 0]) * c["pixel_pitch_mm"], FOCAL_MM, f"{where}: the focal length fx x pixel_pitch_mm [mm]")
    rvec = numbers("rvec", 3)
    angle = float(np.linalg.norm(rvec))
    if angle > np.pi + 1e-6:
        raise ValueError(f"{where}: 'rvec' turns by {angle:g}, more than pi: a rotation vector is in radians, at most "
                         f"pi long (in degrees? {angle:g} deg is {np.deg2rad(angle):.4g} rad)")
    size = tuple(int(x) for x in numbers("image_size", 2))
    dist = np.pad(dist, (0, 5 - dist.size))
    moved = corner_distortion(K, dist, size)
    if not moved <= MAX_DISTORTION:
        raise ValueError(f"{where}: 'dist_coeffs' {dist.tolist()} move the image's corner by {100 * moved:.0f} % of "
                         f"its distance from the centre; lenses move it by a few per cent (at most "
                         f"{100 * MAX_DISTORTION:.0f} %): check k1, k2, k3 (OpenCV's, for coordinates divided by the "
                         "focal length)")
    c.update(size=size, K=K, dist=dist, rvec=rvec, tvec=numbers("tvec", 3))
    return c


def corner_distortion(K: np.ndarray, dist: np.ndarray, size: tuple[int, int]) -> float:
    """How far OpenCV's distortion ``dist`` (k1, k2, p1, p2, k3) moves the image corner farthest from the principal
    point, as a share of that corner's distance from it (``K``: the camera matrix; ``size``: (width, height) px);
    infinite where it folds the image over (the radial factor at or below 0)."""
    w, h = size
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], np.float64)
    x = (corners - K[[0, 1], [2, 2]]) / K[[0, 1], [0, 1]]
    x = x[np.argmax((x * x).sum(1))]
    k1, k2, p1, p2, k3 = dist
    r2 = float(x @ x)
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    if radial <= 0:
        return float("inf")
    dx = x * (radial - 1) + np.array([2 * p1 * x[0] * x[1] + p2 * (r2 + 2 * x[0] ** 2),
                                      p1 * (r2 + 2 * x[1] ** 2) + 2 * p2 * x[0] * x[1]])
    return float(np.linalg.norm(dx) / np.sqrt(r2)) if r2 > 0 else 0.0


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
