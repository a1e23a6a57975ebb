"""The probe box: the voxel grid of the reconstruction and the one place where coordinates are normalised.

World frame in millimetres, origin at the box centre, ``y`` vertical. Volumes are arrays shaped
``(nx, ny, nz)`` with voxel centres at ``-L/2 + (i + 0.5) h``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F


@functools.lru_cache(maxsize=64)
def _constant(values: tuple, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """A small constant tensor made once per dtype and device: on a GPU each ``torch.as_tensor`` of host data is a
    copy that waits for the work queued before it, several times per training step otherwise."""
    return torch.tensor(values, dtype=dtype, device=device)


@dataclass(frozen=True)
class ProbeBox:
    """Axis-aligned box of ``shape`` voxels of size ``voxel_mm``, centred on the origin.

    Attributes:
        shape: (nx, ny, nz) voxels.
        voxel_mm: voxel edge [mm].
    """

    shape: tuple[int, int, int]
    voxel_mm: float

    def __post_init__(self):
        if len(self.shape) != 3 or min(self.shape) < 2:
            raise ValueError(f"probe box shape must be three sizes >= 2, got {self.shape}")
        if not self.voxel_mm > 0:
            raise ValueError(f"voxel size must be positive, got {self.voxel_mm} mm")

    @property
    def extent_mm(self) -> np.ndarray:
        """Edge lengths (Lx, Ly, Lz) [mm]."""
        return np.asarray(self.shape, dtype=np.float64) * self.voxel_mm

    @property
    def half_mm(self) -> np.ndarray:
        return self.extent_mm / 2

    def half_like(self, x: torch.Tensor) -> torch.Tensor:
        """:attr:`half_mm` as a (3,) tensor of ``x``'s dtype and device (made once per dtype and device)."""
        return _constant(tuple(self.half_mm.tolist()), x.dtype, x.device)

    @property
    def scale_mm(self) -> float:
        """Half of the longest edge [mm]: world / scale_mm = network coordinates (isotropic)."""
        return float(self.half_mm.max())

    @property
    def shortest_side_mm(self) -> float:
        return float(self.extent_mm.min())

    def axes(self) -> list[np.ndarray]:
        """Voxel-centre coordinates along x, y, z [mm]."""
        return [(-n / 2 + np.arange(n) + 0.5) * self.voxel_mm for n in self.shape]

    def centres(self) -> np.ndarray:
        """Voxel centres, (nx, ny, nz, 3) [mm]."""
        return np.stack(np.meshgrid(*self.axes(), indexing="ij"), axis=-1)

    # --- coordinate normalisation: the only place world <-> network coordinates meet ---
    def normalize(self, p: torch.Tensor) -> torch.Tensor:
        """World [mm] -> network coordinates: isotropic, the longest edge spans [-1, 1]. (..., 3) -> (..., 3)."""
        return p / self.scale_mm

    def to_grid(self, p: torch.Tensor) -> torch.Tensor:
        """World [mm] -> ``grid_sample`` coordinates (per axis, box faces at -1 and +1). (..., 3) -> (..., 3)."""
        return p / self.half_like(p)

    def from_grid(self, g: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`to_grid`: per-axis [-1, 1] (box faces) -> world [mm]. (..., 3) -> (..., 3)."""
        return g * self.half_like(g)

    def contains(self, p: torch.Tensor) -> torch.Tensor:
        """(..., 3) [mm] -> (...) bool."""
        return (p.abs() <= self.half_like(p)).all(-1)

    def intersect(self, origins: torch.Tensor, dirs: torch.Tensor):
        """Slab test of rays against the box.

        Args:
            origins: (R, 3) [mm]; dirs: (R, 3) unit vectors.
        Returns:
            t_near, t_far: (R,) [mm] along each ray (clamped to t >= 0); hit: (R,) bool (entered over a
            positive length).
        """
        half = self.half_like(dirs)
        safe = torch.where(dirs.abs() < 1e-12, torch.full_like(dirs, 1e-12), dirs)
        inv = 1.0 / safe
        t0 = (-half - origins) * inv
        t1 = (half - origins) * inv
        t_near = torch.minimum(t0, t1).amax(-1).clamp_min(0.0)
        t_far = torch.maximum(t0, t1).amin(-1)
        return t_near, t_far, t_far > t_near + 1e-9


FACES = ("-x", "+x", "-y", "+y", "-z", "+z")


def box_faces(faces) -> list[tuple[int, int]]:
    """Names of box faces -> (axis, side) pairs, side -1 or +1. ``-x``/``+x`` name one face, ``x`` both faces of
    that axis (likewise y, z); the result is sorted and without repeats."""
    out = set()
    for f in faces:
        f = str(f)
        if f in ("x", "y", "z"):
            out |= {("xyz".index(f), -1), ("xyz".index(f), 1)}
        elif f in FACES:
            out.add(("xyz".index(f[1]), -1 if f[0] == "-" else 1))
        else:
            raise ValueError(f"ambient faces must be among x, y, z (both faces of an axis) or {', '.join(FACES)}; "
                             f"got '{f}'")
    return sorted(out)


def face_names(faces: list[tuple[int, int]]) -> list[str]:
    """(axis, side) pairs -> names (``-x``, ``+z``, ...)."""
    return [("-" if side < 0 else "+") + "xyz"[axis] for axis, side in faces]


def sample_volume(volume: torch.Tensor, box: ProbeBox, p: torch.Tensor, padding: str = "zeros") -> torch.Tensor:
    """Trilinear interpolation of a voxel volume at world points. Between the outermost voxel centres and the
    faces, and beyond, ``padding='zeros'`` blends towards zero and ``'border'`` holds the edge values.

    Args:
        volume: (C, nx, ny, nz) or (nx, ny, nz).
        p: (..., 3) points [mm].
    Returns:
        (..., C), or (...) for a 3-D volume.
    """
    squeeze = volume.dim() == 3
    vol = volume[None] if squeeze else volume
    # grid_sample indexes (D, H, W) with grid (x, y, z) -> (W, H, D): store as (C, nz, ny, nx).
    vol = vol.permute(0, 3, 2, 1)[None]
    g = box.to_grid(p).reshape(1, -1, 1, 1, 3).to(vol.dtype)
    out = F.grid_sample(vol, g, mode="bilinear", padding_mode=padding, align_corners=False)
    out = out.reshape(vol.shape[1], -1).T.reshape(*p.shape[:-1], vol.shape[1])
    return out[..., 0] if squeeze else out
