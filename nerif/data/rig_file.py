"""A capture's rig file, ``rig.yaml``: read once and checked into a typed :class:`RigFile`, and written
(:func:`write_rig`), every format version here (1-3: one camera model on an arc, a time series, OpenCV-calibrated
cameras; every key is explained in ``docs/captures.md``)."""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import yaml

from nerif.data.calibration import (DISTANCE_MM, F_NUMBER, FOCAL_MM, PITCH_UM, calibrated_camera, calibration_entry,
                                    plausible, read_calibration)
from nerif.export import atomic_write
from nerif.geometry import Camera, ProbeBox, arc_rig
from nerif.physics import Ambient

RIG_FILE = "rig.yaml"
RIG_VERSION = 2  # what the writer of a steady or time-resolved arc capture writes
CALIBRATED_VERSION = 3  # what the writer of a capture of calibrated cameras writes
READ_VERSIONS = (1, 2, 3)
FORMAT_DOC = "docs/captures.md"
ARC_KEYS = ("focal_mm", "pitch_um", "f_number", "camera_to_centre_mm", "camera_to_background_mm")
# every key a rig file may hold, by version and by block: another key is a slip (a misspelling, another format's)
COMMON_KEYS = ("format", "version", "roi_px", "probe", "ambient", "T_max", "temperature_range_K", "heldout",
               "flame_only", "occluders")
TOP_KEYS = {1: COMMON_KEYS + ("camera", "views"), 2: COMMON_KEYS + ("camera", "views", "frames"),
            3: COMMON_KEYS + ("calibration", "cameras", "f_number")}
BLOCK_KEYS = {"camera": ARC_KEYS + ("sensor_px",), "views": ("angles_deg", "images", "references"),
              "probe": ("shape", "voxel_mm"), "ambient": ("T0", "n0")}
MIN_AMBIENT_K = 150.0  # an ambient temperature below this is not in kelvin (a room in Celsius reads 20-25)


@dataclass(frozen=True)
class RigFrame:
    """One instant of a capture: ``time_s`` [s] and one distorted image per view (relative to the folder): a file,
    or a tuple of files, the exposures of that state (:func:`exposures`)."""

    time_s: float
    images: tuple


@dataclass(frozen=True)
class ArcLens:
    """The one camera model of a version-1/2 rig file, repeated at every angle of an arc: lengths [mm], pitch
    [um]."""

    focal_mm: float
    pitch_um: float
    f_number: float
    camera_to_centre_mm: float
    camera_to_background_mm: float


@dataclass(frozen=True)
class RigFile:
    """What ``rig.yaml`` says of a capture.

    Attributes:
        path: the rig file. version: its format version.
        sensor_px: (width, height) of every image [px]. angles_deg: (V,) the views' azimuths [deg].
        references: (V,) each view's reference image: a file, or a tuple of files, its exposures (averaged).
        frames: the instants, each with V distorted images (as ``references``).
        roi_px: (x, y, width, height) the region of interest on the sensor [px].
        box: the probe box. ambient: T0, n0 and T_max of the gas around the flame.
        heldout: the views never trained on (None: the default,
            :func:`nerif.data.diagnostics.least_unseen_view`).
        temperature_range_K: (low, high) the temperatures the flame lies within, or None.
        lens: the camera model of an arc (versions 1, 2), else None.
        calibrated: the calibrated cameras (version 3, full sensor), else None.
        sources: the files it was read from: the rig file and its calibration file, if any.
        flame_only: (V,) each view's exposure of the flame alone (the background switched off), where the rig
            recorded one (the key ``flame_only``), else None: its light is taken off the distorted image.
        occluders: (V,) each view's mask image of what hides its background (a burner, a mount; nonzero: hidden),
            or None for a view without one (the key ``occluders``); None: none given. Hidden pixels are unknown.
    """

    path: Path
    version: int
    sensor_px: tuple[int, int]
    angles_deg: tuple[float, ...]
    references: tuple
    frames: tuple[RigFrame, ...]
    roi_px: tuple[int, int, int, int]
    box: ProbeBox
    ambient: Ambient
    heldout: Optional[tuple[int, ...]]
    temperature_range_K: Optional[tuple[float, float]]
    lens: Optional[ArcLens] = None
    calibrated: Optional[tuple[Camera, ...]] = None
    sources: tuple[Path, ...] = ()
    flame_only: Optional[tuple[str, ...]] = None
    occluders: Optional[tuple[Optional[str], ...]] = None

    @property
    def root(self) -> Path:
        return self.path.parent

    @property
    def n_views(self) -> int:
        return len(self.angles_deg)

    def cameras(self) -> list[Camera]:
        """The cameras on the full sensor."""
        if self.calibrated is not None:
            return list(self.calibrated)
        w, h = self.sensor_px
        lens = self.lens
        return arc_rig(angles_deg=list(self.angles_deg), distance_mm=lens.camera_to_centre_mm, focal_mm=lens.focal_mm,
                       width_px=w, height_px=h, pitch_um=lens.pitch_um,
                       background_behind_mm=lens.camera_to_background_mm - lens.camera_to_centre_mm,
                       f_number=lens.f_number, binning=1)


def _need(d, key: str, where: str):
    if not isinstance(d, dict) or key not in d or d[key] is None:
        raise ValueError(f"{where} lacks '{key}': see the rig file format in {FORMAT_DOC}")
    return d[key]


def _optional(rig: dict, key: str, default):
    """An optional key: its value, or ``default`` where it is absent or null."""
    value = rig.get(key)
    return default if value is None else value


def _known_keys(path: Path, rig: dict) -> None:
    """One sentence for a key the rig file's version does not know, with the nearest known key."""
    blocks = [("", rig, TOP_KEYS[rig["version"]])] + [(f"{b}.", rig[b], keys) for b, keys in BLOCK_KEYS.items()
                                                     if isinstance(rig.get(b), dict)]
    for prefix, block, keys in blocks:
        for key in block:
            if key not in keys:
                near = difflib.get_close_matches(str(key), keys, n=1, cutoff=0.5)
                hint = f"did you mean '{prefix}{near[0]}'?" if near else f"the keys are {', '.join(keys)}"
                raise ValueError(f"{path}: unknown key '{prefix}{key}' for a version-{rig['version']} rig file: {hint} "
                                 f"(see {FORMAT_DOC})")


def _integers(v, n: Optional[int], what: str) -> tuple[int, ...]:
    """A list of ``n`` whole numbers (any length where None), or one sentence naming ``what``."""
    ok = isinstance(v, list) and (n is None or len(v) == n) and all(
        not isinstance(x, bool) and isinstance(x, (int, float)) and float(x).is_integer() for x in v)
    if not ok:
        size = f"{n} whole numbers" if n is not None else "a list of whole numbers"
        raise ValueError(f"{what} = {v!r} must be {size}")
    return tuple(int(x) for x in v)


def _numbers(v, what: str) -> tuple[float, ...]:
    """A non-empty list of finite numbers, or one sentence naming ``what``."""
    if not isinstance(v, list) or not v or any(isinstance(x, bool) or not isinstance(x, (int, float))
                                               or not np.isfinite(x) for x in v):
        raise ValueError(f"{what} = {v!r} must be a list of numbers (one per view)")
    return tuple(float(x) for x in v)


def _positive(v, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (np.isfinite(v) and v > 0):
        raise ValueError(f"{what} = {v!r} must be a positive number")
    return float(v)


_READ: dict = {}  # resolved rig file -> (the stat of each file it was read from, the RigFile): see read_rig


def _stats(paths) -> tuple:
    """(inode, size, mtime_ns, ctime_ns) of each file, None for one that is gone: a file rewritten or replaced
    differs in one of them."""
    out = []
    for p in paths:
        try:
            st = Path(p).stat()
            out.append((st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns))
        except OSError:
            out.append(None)
    return tuple(out)


def read_rig(root: Path) -> RigFile:
    """``rig.yaml`` of the capture folder ``root``, checked: format, version, required keys, view and frame lists;
    one sentence naming the file and the key otherwise. Read once a process while the rig file and its calibration
    file stay as they were (a run's memory estimate, frames and scene, and every frame of a series, share it)."""
    path = Path(root) / RIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{path} does not exist: a capture folder needs a {RIG_FILE} beside its images")
    key = path.resolve()
    known = _READ.get(key)
    if known is not None and known[0] == _stats(known[1].sources):
        return known[1]
    rig = _read_rig_file(path)
    if len(_READ) >= 8:
        _READ.clear()
    _READ[key] = (_stats(rig.sources), rig)
    return rig


def _read_rig_file(path: Path) -> RigFile:
    """:func:`read_rig` of the file ``path`` itself, every time."""
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
    lens, calibrated = None, None
    if rig["version"] == 3:
        calibrated = _calibrated_cameras(path, rig)
        _known_keys(path, rig)
        w, h = calibrated[0].camera.width, calibrated[0].camera.height
        angles = [round(float(np.degrees(np.arctan2(c.position[0], c.position[2]))), 6) for c in calibrated]
        views = {"angles_deg": angles, "images": [c.image for c in calibrated],
                 "references": [c.reference for c in calibrated]}
        calibrated = tuple(c.camera for c in calibrated)
        roi = _optional(rig, "roi_px", [0, 0, w, h])
    else:
        _known_keys(path, rig)
        lens, (w, h) = _arc_lens(path, rig)
        views = _need(rig, "views", str(path))
        angles = _need(views, "angles_deg", f"{path} views")
        roi = _need(rig, "roi_px", str(path))
    refs = _need(views, "references", f"{path} views")
    angles = _numbers(angles, f"{path}: views.angles_deg")
    frames = _frames(rig, views, len(angles), path)
    if isinstance(refs, list) and len(refs) != len(angles):
        raise ValueError(f"{path}: views.references lists {len(refs)} files for {len(angles)} views; give one "
                         "per view or a single shared file")
    refs = [_exposures_entry(r, f"{path}: views.references[{v}]")
            for v, r in enumerate(refs if isinstance(refs, list) else [refs] * len(angles))]
    box, ambient = _probe_and_ambient(path, rig)
    roi = _integers(roi, 4, f"{path}: roi_px (x, y, width, height)")
    held = rig.get("heldout")
    if held is not None:
        held = _integers(held, None, f"{path}: heldout")
    flame, occluders = _per_view_images(path, rig, len(angles))
    t_range = rig.get("temperature_range_K")
    if t_range is not None:
        lo, hi = _numbers(t_range, f"{path}: temperature_range_K") if isinstance(t_range, list) and \
            len(t_range) == 2 else (0.0, 0.0)
        if not 0 < lo < hi:
            raise ValueError(f"{path}: temperature_range_K {t_range} must be two increasing positive temperatures [K]")
    return RigFile(path, int(rig["version"]), (int(w), int(h)), angles,
                   tuple(refs), frames, roi, box, ambient, held,
                   (lo, hi) if t_range is not None else None, lens, calibrated,
                   (path,) + ((path.parent / str(rig["calibration"]),) if "calibration" in rig else ()),
                   tuple(str(f) for f in flame) if flame is not None else None,
                   tuple(occluders) if occluders is not None else None)


def _per_view_images(path: Path, rig: dict, n_views: int) -> tuple[Optional[list], Optional[list]]:
    """The rig file's ``flame_only`` and ``occluders`` lists (None where absent), each checked to list one image per
    view (an occluder mask may be null)."""
    flame = rig.get("flame_only")
    if flame is not None and (not isinstance(flame, list) or len(flame) != n_views):
        raise ValueError(f"{path}: flame_only must list one image per view ({n_views}), each the view's exposure "
                         "of the flame with the background switched off")
    occluders = rig.get("occluders")
    if occluders is not None and (not isinstance(occluders, list) or len(occluders) != n_views
                                  or not all(o is None or isinstance(o, str) for o in occluders)):
        raise ValueError(f"{path}: occluders must list one mask image per view ({n_views}; null for a view with "
                         "none), nonzero where something hides the background")
    return flame, occluders


def _probe_and_ambient(path: Path, rig: dict) -> tuple[ProbeBox, Ambient]:
    """The rig file's probe grid and ambient gas (with ``T_max``), checked: voxel counts, a temperature in kelvin,
    a gas's refractive index."""
    probe, amb = _need(rig, "probe", str(path)), _need(rig, "ambient", str(path))
    shape = _integers(_need(probe, "shape", f"{path} probe"), 3, f"{path}: probe.shape")
    if min(shape) < 1:
        raise ValueError(f"{path}: probe.shape = {list(shape)} must be three positive voxel counts")
    box = ProbeBox(shape, _positive(_need(probe, "voxel_mm", f"{path} probe"), f"{path}: probe.voxel_mm"))
    t0 = _positive(_need(amb, "T0", f"{path} ambient"), f"{path}: ambient.T0")
    if t0 < MIN_AMBIENT_K:
        raise ValueError(f"{path}: ambient.T0 = {amb['T0']} is not a temperature in kelvin (room temperature is "
                         f"about 293-300 K; {amb['T0']} degC is {t0 + 273.15:g} K)")
    n0 = _positive(_need(amb, "n0", f"{path} ambient"), f"{path}: ambient.n0")
    if not 1.0 < n0 < 1.01:
        raise ValueError(f"{path}: ambient.n0 = {amb['n0']} must be a gas's refractive index, just above 1 (air: "
                         "1.00027)")
    return box, Ambient(t0, n0, _positive(_optional(rig, "T_max", 2000.0), f"{path}: T_max"))


def _arc_lens(path: Path, rig: dict) -> tuple[ArcLens, tuple[int, int]]:
    """The camera model and the sensor size (width, height) of a version-1/2 rig file, checked."""
    cam = _need(rig, "camera", str(path))
    for k in ARC_KEYS + ("sensor_px",):
        _need(cam, k, f"{path} camera")
    values = {k: _positive(cam[k], f"{path}: camera.{k}") for k in ARC_KEYS}
    for key, limits in (("focal_mm", FOCAL_MM), ("pitch_um", PITCH_UM), ("camera_to_centre_mm", DISTANCE_MM),
                        ("camera_to_background_mm", DISTANCE_MM), ("f_number", F_NUMBER)):
        plausible(values[key], limits, f"{path}: camera.{key}")
    if not values["camera_to_background_mm"] > values["camera_to_centre_mm"]:
        raise ValueError(f"{path}: camera.camera_to_background_mm = {cam['camera_to_background_mm']} must exceed "
                         f"camera.camera_to_centre_mm = {cam['camera_to_centre_mm']} (the background lies behind the "
                         "probe)")
    w, h = _integers(cam["sensor_px"], 2, f"{path}: camera.sensor_px (width, height)")
    return ArcLens(**values), (w, h)


@dataclass(frozen=True)
class _Calibrated:
    camera: Camera
    image: str
    reference: str

    @property
    def position(self):
        return self.camera.position


def _calibrated_cameras(path: Path, rig: dict) -> list[_Calibrated]:
    """The cameras of a version-3 rig file, from the calibration file it names or its own ``cameras`` list."""
    if ("calibration" in rig) == ("cameras" in rig):
        raise ValueError(f"{path}: version 3 needs either 'calibration' (an OpenCV calibration file) or a 'cameras' "
                         f"list, {'not both' if 'cameras' in rig else 'one of them'}")
    if "cameras" in rig:
        if not isinstance(rig["cameras"], list) or not rig["cameras"]:
            raise ValueError(f"{path}: 'cameras' must be a list with one entry per camera")
        cal = [calibration_entry(c if isinstance(c, dict) else {}, f"camera {k:02d}", f"{path}: cameras[{k}]")
               for k, c in enumerate(rig["cameras"])]
    else:
        cal = read_calibration(path.parent / str(rig["calibration"]))
    sizes = {c["size"] for c in cal}
    if len(sizes) > 1:
        raise ValueError(f"{path}: the cameras' image sizes differ ({sorted(sizes)}); nerif needs one size for all")
    if len({c["name"] for c in cal}) != len(cal):
        raise ValueError(f"{path}: two cameras share a name")
    f_number = plausible(_positive(_optional(rig, "f_number", 32.0), f"{path}: f_number"), F_NUMBER,
                         f"{path}: f_number")
    return [_Calibrated(calibrated_camera(c, f_number), c["image"], c["reference"]) for c in cal]


def _frames(rig: dict, views: dict, n: int, path: Path) -> tuple[RigFrame, ...]:
    """The frames of a rig file with one image per view: its ``frames`` list (version 2), or its ``views.images``
    as one frame at time 0; checked."""
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
        return (RigFrame(0.0, tuple(_exposures_entry(f, f"{path}: views.images[{v}]") for v, f in enumerate(images))),)
    frames = rig["frames"]
    if not isinstance(frames, list) or not frames:
        raise ValueError(f"{path}: frames must be a list of frames, each with its time_s and images")
    for k, fr in enumerate(frames):
        images = _need(fr, "images", f"{path} frame {k}")
        t = _need(fr, "time_s", f"{path} frame {k}")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t):
            raise ValueError(f"{path}: frame {k}'s time_s = {t!r} must be a number of seconds")
        if not isinstance(images, list) or len(images) != n:
            got = len(images) if isinstance(images, list) else "no list of"
            raise ValueError(f"{path}: frame {k} lists {got} images for {n} views (views.angles_deg): every frame "
                             "needs one image per view, in the order of the angles")
        if k and not float(fr["time_s"]) > float(frames[k - 1]["time_s"]):
            raise ValueError(f"{path}: frame {k} has time_s {fr['time_s']}, not after frame {k - 1}'s "
                             f"{frames[k - 1]['time_s']}: list the frames in time order")
    return tuple(RigFrame(float(fr["time_s"]), tuple(_exposures_entry(f, f"{path}: frames[{k}].images[{v}]")
                                                     for v, f in enumerate(fr["images"])))
                 for k, fr in enumerate(frames))


def _exposures_entry(entry, what: str):
    """One view's image of a rig file: a file name, or a list of file names (its exposures of one state, averaged:
    the noise falls as 1 / sqrt(K)), checked; a list of one is that file."""
    if isinstance(entry, list) and entry and all(isinstance(f, str) and f for f in entry):
        return entry[0] if len(entry) == 1 else tuple(entry)
    if isinstance(entry, str) and entry:
        return entry
    raise ValueError(f"{what} = {entry!r} must be a file name, or a list of file names (the exposures of one state)")


def exposures(entry) -> tuple[str, ...]:
    """The files of one view's image in a :class:`RigFile` (a file, or the tuple of its exposures)."""
    return entry if isinstance(entry, tuple) else (entry,)


def write_rig(root: Path, blocks: dict, box: ProbeBox, ambient: Ambient, heldout: list[int],
              version: int = RIG_VERSION) -> Path:
    """``rig.yaml`` of the capture folder ``root``, written atomically: the format and ``version``, then
    ``blocks`` (the cameras as the version holds them: ``camera`` and ``views`` of an arc, ``calibration`` of
    calibrated cameras, ...), then what every version holds: the probe grid of ``box``, the ``ambient`` gas, its
    ``T_max`` and temperature range, and the ``heldout`` views."""
    if version not in READ_VERSIONS:
        raise ValueError(f"rig file version {version}: this nerif writes versions {READ_VERSIONS}")
    rig = {"format": "nerif-capture", "version": version, **blocks,
           "probe": {"shape": [int(s) for s in box.shape], "voxel_mm": float(box.voxel_mm)},
           "ambient": {"T0": float(ambient.T0), "n0": float(ambient.n0)}, "T_max": float(ambient.T_max),
           "temperature_range_K": [float(ambient.T0), float(ambient.T_max)], "heldout": list(heldout)}
    header = f"# nerif capture rig file, version {version} (format: {FORMAT_DOC}); written from a synthetic scene\n"
    return atomic_write(root / RIG_FILE, lambda t: Path(t).write_text(
        header + yaml.safe_dump(rig, sort_keys=False, default_flow_style=None)))
