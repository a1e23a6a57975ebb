"""Temperature phantoms on a probe box: analytic Phantom 5, a Gaussian blob, an axisymmetric flame from an
(r, y) profile, a turbulent plume, and volumes loaded from files.

Each phantom builder returns a :class:`Phantom`: a temperature volume (nx, ny, nz) [K] on its probe box,
with the ambient state that converts it to refractive index.
"""
from __future__ import annotations

from dataclasses import dataclass
import zipfile
from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import torch

from nerif.geometry import ProbeBox
from nerif.physics import check_temperature, delta_from_n, n_from_delta, n_from_temperature, temperature_from_n
from nerif.registry import Registry

PHANTOMS = Registry("phantom", package="nerif.data")


@dataclass
class Phantom:
    """Attributes: T (nx, ny, nz) [K]; box; T0 [K]; n0; name."""

    T: np.ndarray
    box: ProbeBox
    T0: float
    n0: float
    name: str

    def __post_init__(self):
        if self.T.ndim != 3:
            raise ValueError(f"phantom '{self.name}' must be a 3-D volume (nx, ny, nz), got shape {self.T.shape}")
        if tuple(self.T.shape) != tuple(self.box.shape):
            raise ValueError(f"phantom '{self.name}' has shape {self.T.shape} but its box is {self.box.shape}")
        check_temperature(self.T, f"phantom '{self.name}'")

    @property
    def delta(self) -> np.ndarray:
        return delta_from_n(n_from_temperature(self.T, self.T0, self.n0), self.n0)


def phantom5_temperature(x, y, z, T0: float = 296.15, exp=np.exp):
    """The paper's analytic Phantom 5 [K] at coordinates [mm] (box x, z in [-36, 36], y in [-50, 50]): rises of
    1196.85 K and 696.85 K over the ambient ``T0`` (the paper's: 296.15 K). ``exp``: torch.exp for tensors."""
    def g(x, y, z):
        return exp(-(((3 * z**2 + 3 * x**2) / 20**2 + 3 * y**2 / 80**2 - 0.9) ** 2))

    return (T0 + 1196.85 * g(x, y - 50, z)
            + 696.85 * (g(x, y - 50, z - 25) + g(x, y - 50, z + 25) + g(x, y + 50, z - 25) + g(x, y + 50, z + 25)))


@PHANTOMS.register("phantom5")
def phantom5(shape: Sequence[int] = (36, 50, 36), voxel_mm: float = 2.0, T0: float = 296.15,
             n0: float = 1.00027) -> Phantom:
    """Phantom 5 of the paper sampled at voxel centres (default scene: 2 mm voxels; paper grid: 144 x 200 x 144
    voxels of 0.5 mm), its temperature rises over the ambient ``T0``."""
    box = ProbeBox(tuple(shape), voxel_mm)
    c = box.centres()
    return Phantom(phantom5_temperature(c[..., 0], c[..., 1], c[..., 2], T0), box, T0, n0, "phantom5")


@PHANTOMS.register("gaussian_blob")
def gaussian_blob(shape: Sequence[int] = (40, 40, 40), voxel_mm: float = 1.5, centre_mm=(0.0, 0.0, 0.0),
                  width_mm: float = 8.0, T_peak: float = 1200.0, T0: float = 296.15, n0: float = 1.00027) -> Phantom:
    """A blob Gaussian in refractive index: ``delta = delta_peak exp(-|p - c|^2 / (2 w^2))``, with
    ``delta_peak`` that of ``T_peak``; its deflection is known in closed form (:func:`gaussian_blob_deflection`)."""
    box = ProbeBox(tuple(shape), voxel_mm)
    r2 = ((box.centres() - np.asarray(centre_mm)) ** 2).sum(-1)
    d_peak = delta_from_n(n_from_temperature(T_peak, T0, n0), n0)
    T = temperature_from_n(n_from_delta(d_peak * np.exp(-r2 / (2 * width_mm**2)), n0), T0, n0)
    return Phantom(T, box, T0, n0, "gaussian_blob")


def _cylinder_coordinates(box: ProbeBox) -> tuple[np.ndarray, np.ndarray]:
    """Radius from the y axis and height [mm] at the voxel centres of ``box``."""
    c = box.centres()
    return np.hypot(c[..., 0], c[..., 2]), c[..., 1]


def lifted_jet_profile(r: np.ndarray, y: np.ndarray, T0: float, T_peak: float, lift_mm: float = -30.0,
                       base_radius_mm: float = 12.0, flame_length_mm: float = 55.0, thickness_mm: float = 4.0,
                       spread: float = 0.08, base_mm: float = 3.0, exp=np.exp, tanh=np.tanh,
                       clip=np.clip) -> np.ndarray:
    """A lifted-jet-like flame T(r, y) [K]: a hot conical sheet that stabilises ``lift_mm`` high (over
    ``base_mm``), closes ``flame_length_mm`` above it into a hot core, and thickens with height. ``exp``,
    ``tanh``, ``clip``: torch.exp, torch.tanh, torch.clamp for tensors."""
    h = y - lift_mm
    r_f = base_radius_mm * clip(1 - h / flame_length_mm, 0, 1)
    w = thickness_mm + spread * clip(h, 0, None)
    onset = 0.5 * (1 + tanh(h / base_mm))
    return T0 + (T_peak - T0) * onset * exp(-(((r - r_f) / w) ** 2))


@PHANTOMS.register("axisymmetric")
def axisymmetric(shape: Sequence[int] = (36, 50, 36), voxel_mm: float = 2.0, profile: Optional[str] = None,
                 T_peak: float = 1800.0, T0: float = 296.15, n0: float = 1.00027, **lifted_jet) -> Phantom:
    """An axisymmetric flame (axis y) from an (r, y) temperature profile: a stand-in for the paper's Phantom 1.

    Args:
        profile: a .npz with ``r_mm`` (R,), ``y_mm`` (Y,) and ``T`` (R, Y) [K], interpolated (ambient outside);
            None = :func:`lifted_jet_profile` with ``T_peak`` and the ``lifted_jet`` parameters.
    """
    box = ProbeBox(tuple(shape), voxel_mm)
    r, y = _cylinder_coordinates(box)
    if profile is None:
        T = lifted_jet_profile(r, y, T0, T_peak, **lifted_jet)
    else:
        from scipy.interpolate import RegularGridInterpolator

        with np.load(Path(profile).expanduser()) as f:
            r_ax, y_ax, table = f["r_mm"], f["y_mm"], f["T"]
        if table.shape != (len(r_ax), len(y_ax)):
            raise ValueError(f"{profile}: T must be (len(r_mm), len(y_mm)) = ({len(r_ax)}, {len(y_ax)}), "
                             f"got {table.shape}")
        interp = RegularGridInterpolator((r_ax, y_ax), table, bounds_error=False, fill_value=T0)
        T = interp(np.stack([r, y], -1))
    return Phantom(T, box, T0, n0, "axisymmetric")


@PHANTOMS.register("flicker")
def flicker(shape: Sequence[int] = (36, 50, 36), voxel_mm: float = 2.0, time_s: float = 0.0,
            frequency_hz: float = 12.0, wavelength_mm: float = 40.0, amplitude: float = 0.3, T_peak: float = 1800.0,
            lift_mm: float = -30.0, base_radius_mm: float = 12.0, flame_length_mm: float = 55.0, T0: float = 296.15,
            n0: float = 1.00027, **lifted_jet) -> Phantom:
    """The axisymmetric lifted flame (:func:`lifted_jet_profile`) puffing: its sheet radius modulated by a
    varicose wave travelling up at ``frequency_hz * wavelength_mm`` [mm/s], ``1 + a(h) sin(2 pi (h / wavelength
    - frequency t))``, whose relative amplitude ``a(h)`` grows from 0 at the flame base (height ``h = y - lift``)
    to ``amplitude`` at its tip; a snapshot at ``time_s`` (one state of a flickering flame, periodic in
    1 / ``frequency_hz``)."""
    box = ProbeBox(tuple(shape), voxel_mm)
    r, y = _cylinder_coordinates(box)
    h = y - lift_mm
    a = amplitude * np.clip(h / flame_length_mm, 0.0, 1.0)
    radius = base_radius_mm * (1.0 + a * np.sin(2 * np.pi * (h / wavelength_mm - frequency_hz * time_s)))
    T = lifted_jet_profile(r, y, T0, T_peak, lift_mm=lift_mm, base_radius_mm=radius,
                           flame_length_mm=flame_length_mm, **lifted_jet)
    return Phantom(T, box, T0, n0, "flicker")


def kolmogorov_field(shape: Sequence[int], voxel_mm: float, seed: int, largest_mm: float) -> np.ndarray:
    """A zero-mean, unit-variance random field whose energy spectrum falls as k^(-5/3) (amplitude k^(-11/6) in
    3-D) below the scale ``largest_mm``; seeded."""
    rng = np.random.default_rng(seed)
    k = np.meshgrid(*[np.fft.fftfreq(n, voxel_mm) for n in shape[:2]], np.fft.rfftfreq(shape[2], voxel_mm),
                    indexing="ij")
    kk = np.sqrt(sum(ki**2 for ki in k))
    amp = np.maximum(kk, 1.0 / largest_mm) ** (-11.0 / 6.0)
    amp[0, 0, 0] = 0.0
    noise = np.fft.rfftn(rng.standard_normal(tuple(shape)))
    f = np.fft.irfftn(noise * amp, s=tuple(shape), axes=(0, 1, 2))
    return (f - f.mean()) / f.std()


@PHANTOMS.register("turbulent_plume")
def turbulent_plume(shape: Sequence[int] = (36, 50, 36), voxel_mm: float = 2.0, T_peak: float = 1600.0,
                    radius_mm: float = 8.0, spread: float = 0.06, fluctuation: float = 0.35, largest_mm: float = 20.0,
                    T_min: Optional[float] = None, T_max: float = 2200.0, seed: int = 0, T0: float = 296.15,
                    n0: float = 1.00027) -> Phantom:
    """A turbulent plume: a smooth envelope (Gaussian in r cut at 5% of its peak, widening with height) times
    ``1 + fluctuation * F`` with F a seeded -5/3-spectrum field; temperatures clipped to ``[T_min, T_max]``
    (``T_min`` = T0)."""
    box = ProbeBox(tuple(shape), voxel_mm)
    r, y = _cylinder_coordinates(box)
    R = radius_mm + spread * (y - y.min())
    envelope = np.clip((np.exp(-0.5 * (r / R) ** 2) - 0.05) / 0.95, 0, None) * (radius_mm / R) ** 0.5
    F = kolmogorov_field(box.shape, voxel_mm, seed, largest_mm)
    T = T0 + (T_peak - T0) * envelope * (1 + fluctuation * F)
    return Phantom(np.clip(T, T0 if T_min is None else T_min, T_max), box, T0, n0, "turbulent_plume")


def gaussian_blob_deflection(origins: torch.Tensor, dirs: torch.Tensor, centre_mm, width_mm: float,
                             delta_peak: float) -> torch.Tensor:
    """Closed-form deflection of an unbounded Gaussian blob of delta along straight rays.

    ``eps = -delta_peak sqrt(2 pi) / w * q exp(-|q|^2 / (2 w^2))`` with q the vector from the blob centre to
    the ray's closest point. origins, dirs (R, 3) -> (R, 3) [rad].
    """
    c = torch.as_tensor(centre_mm, dtype=dirs.dtype, device=dirs.device)
    rel = origins - c
    q = rel - (rel * dirs).sum(-1, keepdim=True) * dirs
    q2 = (q * q).sum(-1, keepdim=True)
    return -delta_peak * (2 * np.pi) ** 0.5 / width_mm * q * torch.exp(-q2 / (2 * width_mm**2))


def _read_array(path: Path, key: Optional[str]) -> np.ndarray:
    """The volume in ``path`` (never unpickling anything); one sentence naming the file when it is unreadable."""
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".npz", ".mat", ".h5", ".hdf5"):
        raise ValueError(f"cannot read volume file {path}: use .npy, .npz, .mat, .h5 or .hdf5")
    try:
        return _read_store(path, suffix, key)
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as e:
        if isinstance(e, ValueError) and str(e).startswith(str(path)):
            raise  # our own sentence
        raise ValueError(f"cannot read volume file {path}: it is not a valid {suffix} file (corrupt, truncated, or "
                         "holding pickled objects, which nerif does not load)") from None


def _read_store(path: Path, suffix: str, key: Optional[str]) -> np.ndarray:
    if suffix == ".npy":
        return np.load(path, allow_pickle=False)
    if suffix in (".npz", ".mat", ".h5", ".hdf5"):
        if suffix == ".npz":
            with np.load(path, allow_pickle=False) as f:
                store = {k: f[k] for k in f.files}
        elif suffix == ".mat":
            try:
                import scipy.io

                store = {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
            except NotImplementedError:  # MATLAB v7.3 files are HDF5
                store = None
        if suffix in (".h5", ".hdf5") or (suffix == ".mat" and store is None):
            import h5py

            with h5py.File(path, "r") as f:
                store = {k: np.asarray(f[k]) for k in f.keys() if isinstance(f[k], h5py.Dataset)}
                if suffix == ".mat":  # MATLAB stores arrays column-major
                    store = {k: v.T for k, v in store.items()}
        if key is None:
            if len(store) != 1:
                raise ValueError(f"{path} holds {sorted(store)}; set phantom.key to the volume's name")
            key = next(iter(store))
        if key not in store:
            raise ValueError(f"{path} has no array '{key}'; it holds {sorted(store)}")
        return np.asarray(store[key])


def read_volume(path: str, what: str, key: Optional[str] = None) -> np.ndarray:
    """A finite volume (nx, ny, nz) from a ``.npy/.npz/.mat/.h5`` file, as float64; one sentence naming ``what``
    (the setting) and the file when it does not exist or is not such a volume."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(f"{what}: volume file {p} does not exist")
    vol = _read_array(p, key).astype(np.float64)
    if vol.ndim != 3:
        raise ValueError(f"{p}: the volume must have rank 3 (nx, ny, nz), got shape {vol.shape}")
    if not np.all(np.isfinite(vol)):
        raise ValueError(f"{p}: the volume contains {int(np.sum(~np.isfinite(vol)))} NaN or infinite values")
    return vol


@PHANTOMS.register("file")
def volume_file(path: str, voxel_mm: float, T0: float, n0: float, quantity: str = "temperature",
                key: Optional[str] = None) -> Phantom:
    """A volume (nx, ny, nz) of temperature [K] or refractive index from ``.npy/.npz/.mat/.h5`` (e.g. a DNS
    snapshot), with its voxel size [mm] and ambient state; the box is centred on the volume."""
    if quantity not in ("temperature", "n"):
        raise ValueError(f"phantom.quantity must be 'temperature' or 'n', got '{quantity}'")
    p = Path(path).expanduser()
    vol = read_volume(path, "phantom.path", key)
    if quantity == "n":
        if vol.min() <= 1.0:
            raise ValueError(f"{p}: refractive index must exceed 1 everywhere, found {vol.min()}")
        vol = temperature_from_n(vol, T0, n0)
    return Phantom(vol, ProbeBox(tuple(vol.shape), float(voxel_mm)), float(T0), float(n0), p.stem)
