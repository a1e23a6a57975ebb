"""Pinhole cameras of a BOS rig focused on the background plane, and their rays.

Camera frame as in OpenCV: x right, y down (image rows), z forward. Pixel (i, j) = (column, row);
its centre is at (i + 0.5, j + 0.5) (OpenCV puts it at (i, j): its principal point is ours less 0.5). A calibrated
camera may have its principal point off the sensor centre, a focal length in rows that differs from the one in
columns, and OpenCV's lens distortion (k1, k2, p1, p2, k3): a pixel's ray then leaves from its undistorted
position, while images stay on the distorted pixel grid.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Optional

import numpy as np
import torch

from nerif.registry import Registry

RIGS = Registry("rig", package="nerif.geometry")


@dataclass(frozen=True)
class Camera:
    """A pinhole camera.

    Attributes:
        position: camera centre (3,) [mm], world frame.
        rotation: camera-to-world rotation (3, 3); columns are the right, down and forward axes.
        image_distance_mm: lens-to-sensor distance, the pinhole focal length [mm].
        pitch_mm: pixel pitch [mm].
        width, height: sensor size [px].
        f_number: lens f-number.
        background_mm: distance from the camera to the background plane along its axis [mm].
        focal_mm: lens focal length [mm].
        name: label used in messages.
        binning: how many sensor pixels one pixel of this camera spans per side (see :meth:`binned`).
        centre_px: principal point (column, row) [px of this camera, pixel centres at +0.5]; None: the sensor
            centre.
        aspect: focal length in rows over that in columns (fy / fx).
        distortion: OpenCV's (k1, k2, p1, p2, k3) of normalised image coordinates; None: none.
    """

    position: np.ndarray
    rotation: np.ndarray
    image_distance_mm: float
    pitch_mm: float
    width: int
    height: int
    f_number: float
    background_mm: float
    focal_mm: float
    name: str = "camera"
    binning: int = 1
    centre_px: Optional[tuple[float, float]] = None
    aspect: float = 1.0
    distortion: Optional[tuple[float, float, float, float, float]] = None

    def __post_init__(self):
        for key in ("image_distance_mm", "pitch_mm", "f_number", "background_mm", "focal_mm"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise ValueError(f"{self.name}: {key} = {v} must be a positive length (or number): check the rig")
        if not (self.width >= 1 and self.height >= 1):
            raise ValueError(f"{self.name}: a sensor of {self.width} x {self.height} px")
        R = np.asarray(self.rotation, dtype=np.float64)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError(f"{self.name}: its rotation is not a rotation (orthonormal, determinant +1)")

    def fingerprint(self) -> list:
        """Every attribute but the name, as plain numbers and lists: what a cache of anything this camera renders
        must be keyed on (a new attribute joins it by itself)."""
        def plain(v):
            v = np.asarray(v).tolist() if isinstance(v, (np.ndarray, np.generic)) else v
            return [plain(x) for x in v] if isinstance(v, (list, tuple)) else v

        return [plain(getattr(self, f.name)) for f in fields(self) if f.name != "name"]

    @property
    def principal_point(self) -> tuple[float, float]:
        return (self.width / 2.0, self.height / 2.0) if self.centre_px is None else tuple(self.centre_px)

    @property
    def focal_px(self) -> tuple[float, float]:
        """(fx, fy): the pinhole focal length in this camera's columns and rows [px]."""
        fx = self.image_distance_mm / self.pitch_mm
        return fx, fx * self.aspect

    def camera_matrix(self) -> np.ndarray:
        """OpenCV's 3 x 3 K of this camera (pixel centres at integer coordinates)."""
        (fx, fy), (cx, cy) = self.focal_px, self.principal_point
        return np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])

    def binned(self, factor: int) -> "Camera":
        """The same optics read out with ``factor x factor`` pixel binning."""
        if factor < 1 or self.width % factor or self.height % factor:
            raise ValueError(f"binning {factor} must divide the sensor size {self.width} x {self.height} px")
        centre = None if self.centre_px is None else (self.centre_px[0] / factor, self.centre_px[1] / factor)
        return replace(self, pitch_mm=self.pitch_mm * factor, width=self.width // factor, height=self.height // factor,
                       binning=self.binning * factor, centre_px=centre)

    def unbinned(self, factor: int) -> "Camera":
        """The full sensor of a camera read out with ``factor x factor`` binning (inverse of :meth:`binned`)."""
        centre = None if self.centre_px is None else (self.centre_px[0] * factor, self.centre_px[1] * factor)
        return replace(self, pitch_mm=self.pitch_mm / factor, width=self.width * factor, height=self.height * factor,
                       binning=max(self.binning // factor, 1), centre_px=centre)

    @property
    def full_sensor(self) -> "Camera":
        """This camera as its full sensor reads it, unbinned (:meth:`unbinned` by its own :attr:`binning`)."""
        return self.unbinned(self.binning)

    def normalised(self, pixels: np.ndarray) -> np.ndarray:
        """Pixel positions (N, 2) (column, row; centres at +0.5) -> undistorted normalised image coordinates (N, 2)
        (x / z, y / z in the camera frame): OpenCV's iterative undistortion, run to 1e-14."""
        pixels = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        if self.distortion is None:
            (fx, fy), (cx, cy) = self.focal_px, self.principal_point
            return np.stack([(pixels[:, 0] - cx) / fx, (pixels[:, 1] - cy) / fy], -1)
        import cv2

        pts = (pixels - 0.5).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
        out = cv2.undistortPoints(pts, self.camera_matrix(), np.asarray(self.distortion, dtype=np.float64),
                                  R=None, P=None, criteria=criteria)
        return out.reshape(-1, 2)

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Undistorted normalised coordinates (..., 2) -> pixel positions (..., 2) (centres at +0.5): OpenCV's
        model, as ``cv2.projectPoints`` applies it."""
        x, y = xy[..., 0], xy[..., 1]
        if self.distortion is not None:
            k1, k2, p1, p2, k3 = self.distortion
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
                    y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)
        (fx, fy), (cx, cy) = self.focal_px, self.principal_point
        return np.stack([fx * x + cx, fy * y + cy], -1)

    def pixel_directions(self, dtype=torch.float64) -> torch.Tensor:
        """Unit ray directions through every pixel centre, (height * width, 3), row-major (row j, column i)."""
        if self.distortion is None:
            j, i = torch.meshgrid(torch.arange(self.height, dtype=dtype), torch.arange(self.width, dtype=dtype),
                                  indexing="ij")
            cx, cy = self.principal_point
            k = self.pitch_mm / self.image_distance_mm
            d_cam = torch.stack([(i + 0.5 - cx) * k, (j + 0.5 - cy) * (k / self.aspect), torch.ones_like(i)],
                                -1).reshape(-1, 3)
            d = d_cam @ torch.as_tensor(self.rotation, dtype=dtype).T
            return d / d.norm(dim=-1, keepdim=True)
        j, i = np.meshgrid(np.arange(self.height, dtype=np.float64), np.arange(self.width, dtype=np.float64),
                           indexing="ij")
        xy = self.normalised(np.stack([i.reshape(-1) + 0.5, j.reshape(-1) + 0.5], -1))
        d_cam = np.concatenate([xy, np.ones((len(xy), 1))], -1)
        d = torch.as_tensor(d_cam @ np.asarray(self.rotation, dtype=np.float64).T, dtype=dtype)
        return d / d.norm(dim=-1, keepdim=True)

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) [mm] -> pixel coordinates (..., 2) as (column, row), continuous."""
        pc = (np.asarray(points) - self.position) @ self.rotation
        return self.distort(pc[..., :2] / pc[..., 2:3])

    def pixels_per_mm(self, point) -> float:
        """The image scale at a world point (3,) [mm]: pixels per mm of a length across the line of sight there."""
        depth = float((np.asarray(point, dtype=np.float64) - self.position) @ self.rotation[:, 2])
        return self.image_distance_mm / (self.pitch_mm * depth)


def camera_from_nerf_pose(c2w, focal_px: float, width: int, height: int, cx: float, cy: float, pitch_mm: float,
                          length_mm: float, f_number: float, background_mm: float, focal_mm: float,
                          name: str = "camera") -> Camera:
    """A camera from a NeRF-style pose (camera-to-world 4 x 4, OpenGL axes: x right, y up, looking along -z).

    Args:
        c2w: (4, 4) or (3, 4) pose; translation in units of ``length_mm`` millimetres.
        focal_px, cx, cy: intrinsics [px]; the principal point must be the sensor centre.
        pitch_mm: pixel pitch [mm]. f_number, background_mm, focal_mm: optics the pose does not hold.

    A pose whose rotation has determinant -1 (a reflection, as in the BOS paper's datasets) is read the way
    the paper authors' loader reads it: it renders image columns right to left, which is the same as negating
    the right axis, and the result is a proper rotation again.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    if c2w.shape not in ((4, 4), (3, 4)):
        raise ValueError(f"{name}: a pose must be a 4 x 4 or 3 x 4 matrix, got shape {c2w.shape}")
    if not (np.isfinite(focal_px) and focal_px > 0):
        raise ValueError(f"{name}: the focal length fl_x = {focal_px} px must be positive")
    if not np.all(np.isfinite(c2w)):
        raise ValueError(f"{name}: the pose is not finite ({int(np.sum(~np.isfinite(c2w)))} NaN or infinite entries)")
    if abs(cx - width / 2) > 1e-6 or abs(cy - height / 2) > 1e-6:
        raise ValueError(f"{name}: principal point ({cx}, {cy}) px is not the sensor centre "
                         f"({width / 2}, {height / 2}); off-centre principal points are not supported")
    R = c2w[:3, :3] @ np.diag([1.0, -1.0, -1.0])  # OpenGL (right, up, back) -> (right, down, forward)
    det = np.linalg.det(R)
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6):
        raise ValueError(f"{name}: the pose's rotation part is not orthonormal")
    if det < 0:
        R[:, 0] = -R[:, 0]
    return Camera(c2w[:3, 3] * length_mm, R, focal_px * pitch_mm, pitch_mm, int(width), int(height),
                  float(f_number), float(background_mm), float(focal_mm), name=name)


def rig_axis(cameras: list[Camera]) -> np.ndarray:
    """(3,) the unit axis a rig turns about: the normal of the plane its viewing axes lie nearest (the direction
    they have least of), pointing up (+y) where it is not horizontal. A rotating burner's: its vertical axis."""
    axes = np.stack([np.asarray(c.rotation, dtype=np.float64)[:, 2] for c in cameras])
    normal = np.linalg.eigh(axes.T @ axes)[1][:, 0]
    return -normal if normal[1] < 0 else normal


def look_at_origin(position: np.ndarray) -> np.ndarray:
    """Camera-to-world rotation of a camera at ``position`` looking at the origin, image rows along -y."""
    forward = -np.asarray(position, dtype=np.float64)
    forward /= np.linalg.norm(forward)
    down = np.array([0.0, -1.0, 0.0])
    right = np.cross(down, forward)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=1)


@RIGS.register("arc")
def arc_rig(
    n_cameras: int = 12,
    span_deg: float = 165.0,
    distance_mm: float = 800.0,
    focal_mm: float = 105.0,
    width_px: int = 720,
    height_px: int = 1280,
    pitch_um: float = 20.0,
    background_behind_mm: float = 800.0,
    f_number: float = 32.0,
    binning: int = 8,
    angles_deg: Optional[list[float]] = None,
) -> list[Camera]:
    """Cameras evenly over ``span_deg`` on an arc in the x-z plane, all looking at the origin and focused
    on a background plane ``background_behind_mm`` behind the centre (paper defaults).

    Camera k sits at angle ``theta_k = k * span / (n - 1)`` from +z towards +x (or ``angles_deg[k]`` when given,
    which then sets the number of cameras): position ``distance * (sin theta, 0, cos theta)``. A burner turned by
    +theta about y in front of a fixed camera is the same as the camera at -theta.
    """
    if angles_deg is not None:
        n_cameras = len(angles_deg)
    if n_cameras < 1:
        raise ValueError(f"a rig needs at least one camera, got {n_cameras}")
    if isinstance(binning, bool) or not isinstance(binning, int) or binning < 1:
        raise ValueError(f"rig.binning={binning}: pixel binning must be a whole number of at least 1 (1 = the full "
                         "sensor)")
    for key, v in (("distance_mm", distance_mm), ("focal_mm", focal_mm), ("pitch_um", pitch_um),
                   ("background_behind_mm", background_behind_mm), ("f_number", f_number)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
            raise ValueError(f"rig.{key}={v} must be a positive number"
                             + (" (the background lies behind the probe centre)" if key == "background_behind_mm" else ""))
    background_mm = distance_mm + background_behind_mm
    if not focal_mm < background_mm:
        raise ValueError(f"a {focal_mm} mm lens cannot focus on a background {background_mm} mm away")
    image_distance = 1.0 / (1.0 / focal_mm - 1.0 / background_mm)
    if angles_deg is not None:
        angles = np.deg2rad(np.asarray(angles_deg, dtype=np.float64))
    else:
        angles = np.linspace(0.0, np.deg2rad(span_deg), n_cameras) if n_cameras > 1 else np.zeros(1)
    cams = []
    for k, th in enumerate(angles):
        pos = distance_mm * np.array([np.sin(th), 0.0, np.cos(th)])
        cam = Camera(pos, look_at_origin(pos), image_distance, pitch_um * 1e-3, width_px, height_px,
                     f_number, background_mm, focal_mm, name=f"camera {k:02d} ({np.rad2deg(th):.1f} deg)")
        cams.append(cam.binned(binning) if binning > 1 else cam)
    return cams


def look_at(position: np.ndarray, target: np.ndarray, roll_deg: float = 0.0) -> np.ndarray:
    """Camera-to-world rotation of a camera at ``position`` looking at ``target``, image rows along -y, turned
    by ``roll_deg`` about its axis."""
    R = look_at_origin(np.asarray(position, dtype=np.float64) - np.asarray(target, dtype=np.float64))
    c, s = np.cos(np.deg2rad(roll_deg)), np.sin(np.deg2rad(roll_deg))
    right, down = R[:, 0] * c + R[:, 1] * s, -R[:, 0] * s + R[:, 1] * c
    return np.stack([right, down, R[:, 2]], axis=1)


@RIGS.register("calibrated")
def calibrated_rig(n_cameras: int = 10, span_deg: float = 160.0, azimuth_jitter_deg: float = 4.0,
                   distance_mm: tuple = (740.0, 900.0), height_mm: float = 35.0, aim_mm: float = 3.0,
                   roll_deg: float = 2.0, background_behind_mm: tuple = (600.0, 900.0), focal_mm: float = 105.0,
                   width_px: int = 360, height_px: int = 640, pitch_um: float = 40.0, f_number: float = 32.0,
                   principal_offset_px: float = 12.0, k1: tuple = (-0.25, 0.1), k2: tuple = (-0.5, 0.5),
                   tangential: float = 1e-3, binning: int = 4, seed: int = 0) -> list[Camera]:
    """Cameras placed by hand around the burner, as a real tomographic BOS rig is, each with its own lens (seeded):
    camera k near azimuth ``k span / (n - 1)`` (jittered by up to ``azimuth_jitter_deg``), at a distance within
    ``distance_mm`` of the axis and a height within ``height_mm`` of the probe centre, aimed at a point within
    ``aim_mm`` of it, rolled by up to ``roll_deg``, with its own background ``background_behind_mm`` behind the
    centre (focused on it), its principal point up to ``principal_offset_px`` (full-sensor px) off the sensor
    centre and OpenCV's distortion: k1, k2 within their intervals, p1, p2 within +-``tangential``, k3 = 0."""
    if not (isinstance(n_cameras, int) and n_cameras >= 1):
        raise ValueError(f"rig.n_cameras={n_cameras}: a whole number of at least 1")
    arc_rig(n_cameras=1, distance_mm=float(min(distance_mm)), focal_mm=focal_mm, pitch_um=pitch_um,
            background_behind_mm=float(min(background_behind_mm)), f_number=f_number, binning=binning,
            width_px=width_px, height_px=height_px)  # the settings' checks, one sentence each
    rng = np.random.default_rng(seed)
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    cams = []
    for k in range(n_cameras):
        theta = np.deg2rad(k * span_deg / max(n_cameras - 1, 1) + u(-azimuth_jitter_deg, azimuth_jitter_deg))
        d = u(*distance_mm)
        pos = np.array([d * np.sin(theta), u(-height_mm, height_mm), d * np.cos(theta)])
        R = look_at(pos, rng.uniform(-aim_mm, aim_mm, 3), u(-roll_deg, roll_deg))
        background = float(-pos @ R[:, 2]) + u(*background_behind_mm)
        s_i = 1.0 / (1.0 / focal_mm - 1.0 / background)
        centre = (width_px / 2 + u(-principal_offset_px, principal_offset_px),
                  height_px / 2 + u(-principal_offset_px, principal_offset_px))
        dist = (u(*k1), u(*k2), u(-tangential, tangential), u(-tangential, tangential), 0.0)
        cam = Camera(pos, R, s_i, pitch_um * 1e-3, width_px, height_px, f_number, background, focal_mm,
                     name=f"camera {k:02d} ({np.rad2deg(theta):.1f} deg)", centre_px=centre, distortion=dist)
        cams.append(cam.binned(binning) if binning > 1 else cam)
    return cams
