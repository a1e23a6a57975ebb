"""Writing results: atomic file writes, volumes (.npz and VTK .vti for ParaView), JSON metrics, PNG images."""
from __future__ import annotations

import base64
import errno
import json
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Optional
from xml.sax.saxutils import escape

import numpy as np


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write(path: Path, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` then rename onto ``path``: a crash never leaves a half-written file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes files private; outputs get the usual permissions
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def tensor_bytes(obj) -> int:
    """The bytes of every tensor in ``obj`` (nested dicts, lists, tuples): about what ``torch.save`` writes."""
    import torch  # here, not at the top: a bad setting is said before torch's seconds of import

    if isinstance(obj, torch.Tensor):
        return obj.numel() * obj.element_size()
    if isinstance(obj, dict):
        return sum(tensor_bytes(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(tensor_bytes(v) for v in obj)
    return 0


def atomic_save_torch(obj, path: Path) -> Path:
    """``torch.save`` of ``obj`` to ``path``, atomically; a failed write is an :class:`OSError`, as any other file's.
    torch's zip writer reports a full disk in several words ("PytorchStreamWriter failed writing file", "[enforce
    fail at inline_container.cc] . unexpected pos"): the cause is read from the file system instead, a disk with
    less free space than the object's tensors being full whatever the message."""
    import torch

    def write(tmp):
        try:
            torch.save(obj, tmp)
        except RuntimeError as e:
            free = shutil.disk_usage(Path(tmp).parent).free  # the partial file still holds its share
            if free < max(1 << 20, tensor_bytes(obj)):
                raise OSError(errno.ENOSPC, f"No space left on device ({free / 2**20:.1f} MiB free)") from e
            if "inline_container" not in str(e) and "writ" not in str(e):  # not a failed write: a bug, as it is
                raise
            raise OSError(errno.EIO, str(e).strip().splitlines()[-1]) from e

    return atomic_write(path, write)


def strict_json(obj):
    """``obj`` with every NaN or infinite float replaced by None (``null``: strict JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    return obj


def write_json(obj: dict, path: Path) -> Path:
    """``obj`` as strict JSON (NaN and infinities as ``null``), atomically."""
    def write(tmp):
        with open(tmp, "w") as f:
            json.dump(strict_json(obj), f, indent=2, sort_keys=True, allow_nan=False)
            f.write("\n")

    return atomic_write(path, write)


def write_npz(path: Path, units: Optional[dict] = None, **arrays) -> Path:
    """``arrays`` as a compressed ``.npz``, atomically; ``units`` (name -> unit) as its ``units`` entry, a JSON
    string (``json.loads(str(np.load(path)["units"]))``)."""
    if units:
        arrays["units"] = np.array(json.dumps({k: units[k] for k in arrays if k in units}))

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)

    return atomic_write(path, write)


def write_vti(path: Path, voxel_mm: float, origin_mm, units: Optional[dict] = None, **volumes: np.ndarray) -> Path:
    """VTK XML ImageData (ParaView): point data on the voxel centres, x fastest; lengths in mm. ``units``: array
    name -> unit, written as the field data ``units`` (strings ``"NAME: UNIT"``, one an array; ParaView shows them
    under Information) and as ``units`` on each array."""
    shape = next(iter(volumes.values())).shape
    units = units or {}
    arrays = []
    for name, vol in volumes.items():
        raw = np.asarray(vol, dtype="<f4").ravel(order="F").tobytes()
        payload = base64.b64encode(np.uint32(len(raw)).tobytes() + raw).decode()
        unit = f' units="{escape(units[name], {chr(34): "&quot;"})}"' if name in units else ""
        arrays.append(f'<DataArray type="Float32" Name="{name}"{unit} format="binary">{payload}</DataArray>')
    field = ""
    if units:
        words = [f"{k}: {units[k]}" for k in volumes if k in units] + ["lengths: mm"]
        codes = " ".join(" ".join(map(str, w.encode("utf-8") + b"\0")) for w in words)
        field = (f'<FieldData>\n<Array type="String" Name="units" NumberOfTuples="{len(words)}" format="ascii">'
                 f"{codes}</Array>\n</FieldData>\n")
    extent = " ".join(f"0 {n - 1}" for n in shape)
    text = (
        '<?xml version="1.0"?>\n<VTKFile type="ImageData" version="0.1" byte_order="LittleEndian" header_type="UInt32">\n'
        f'<ImageData WholeExtent="{extent}" Origin="{" ".join(map(str, origin_mm))}" '
        f'Spacing="{voxel_mm} {voxel_mm} {voxel_mm}">\n{field}<Piece Extent="{extent}">\n'
        f'<PointData Scalars="{next(iter(volumes))}">\n' + "\n".join(arrays) + "\n</PointData>\n</Piece>\n"
        "</ImageData>\n</VTKFile>\n"
    )

    def write(tmp):
        with open(tmp, "w") as f:
            f.write(text)

    return atomic_write(path, write)


def to_uint8(image) -> np.ndarray:
    """Intensities in [0, 1] -> 8-bit (rounded, clipped), as a camera saves them."""
    return np.clip(np.rint(np.asarray(image) * 255.0), 0, 255).astype(np.uint8)


def write_png(path: Path, image: np.ndarray) -> Path:
    """An 8- or 16-bit image (H, W) or (H, W, C) as a PNG, atomically."""
    import cv2

    ok, png = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"could not encode {path} as PNG (dtype {image.dtype}, shape {image.shape})")
    return atomic_write(Path(path), lambda t: Path(t).write_bytes(png.tobytes()))


def write_pvd(path: Path, datasets: list[tuple[float, str]]) -> Path:
    """A ParaView collection (``.pvd``): one animated dataset of ``(time [s], file)`` pairs, each file a path
    relative to the ``.pvd``'s folder (a frame's ``.vti``)."""
    rows = "\n".join(f'    <DataSet timestep="{float(t)!r}" part="0" file="{Path(f).as_posix()}"/>' for t, f in datasets)
    text = ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
            f"  <Collection>\n{rows}\n  </Collection>\n</VTKFile>\n")
    return atomic_write(path, lambda tmp: Path(tmp).write_text(text))
