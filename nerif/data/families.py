"""Families of analytic flames for benchmarking, rendered independently of every solver's forward model.

A flame is a smooth function sigma(p) of position p [mm] (torch, differentiable). Its deflections are the
integrals of grad sigma along straight rays through the probe box, by composite Simpson quadrature of the
autograd gradient at a step far finer than any reconstruction grid (:func:`render`); the Gaussian blobs that
two families are made of also have a closed form (:func:`blob_deflection`), against which the quadrature is
tested. No voxel grid, trilinear interpolation or network enters the rendering.

Families (``FAMILIES``; each ``family(seed) -> Flame``):

- ``plumes``: two or three smooth plumes, chains of Gaussian blobs twisting up a helix and widening with height;
- ``eddies``: multi-scale eddies, 40 Gaussian blobs of 1-6 mm (log-uniform) in a cone;
- ``phantom5``: the paper's analytic Phantom 5 (its lobes cut by the z faces of its box);
- ``axisymmetric``: the lifted-jet flame of :func:`nerif.data.phantoms.lifted_jet_profile`;
- ``turbulent``: a widening plume times a log-normal random field of 48 Fourier modes with a -5/3 spectrum.

Temperatures follow from sigma with the families' ambient state (T0 = 300 K, T_max = 2400 K: sigma = -1).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import torch

from nerif.data.phantoms import lifted_jet_profile, phantom5_temperature
from nerif.data.synthetic import with_noise
from nerif.data.transforms import write_split
from nerif.geometry import ProbeBox, arc_rig, rays_in_box, view_index
from nerif.export import atomic_write
from nerif.physics import Ambient
from nerif.renderers.deflection import perpendicular

AMBIENT = Ambient(300.0, 1.00027, 2400.0)


@dataclass
class Flame:
    """A flame of a family.

    Attributes:
        sigma: p (..., 3) [mm] float64 -> sigma (...), differentiable.
        box: the probe box it is reconstructed on (1 mm voxels).
        name: family and seed.
        finest_mm: its finest feature [mm] (sets the quadrature step).
        blobs: (centres (K, 3) [mm], widths (K,) [mm], amplitudes (K,) of sigma) when it is a sum of Gaussian blobs.
    """

    sigma: Callable[[torch.Tensor], torch.Tensor]
    box: ProbeBox
    name: str
    finest_mm: float
    blobs: tuple | None = None

    def truth_T(self) -> np.ndarray:
        """True temperature [K] at the box's voxel centres, (nx, ny, nz)."""
        p = torch.as_tensor(self.box.centres(), dtype=torch.float64)
        with torch.no_grad():
            return AMBIENT.temperature_from_sigma(self.sigma(p).numpy())

    def render(self, origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Deflections of sigma (R, 3) and path integrals of sigma (R,) [mm] of rays (R, 3) (float64): in closed
        form for sums of blobs, else by quadrature at an eighth of the finest feature."""
        if self.blobs is not None:
            return blob_deflection(*self.blobs, self.box, origins, dirs)
        return render(self.sigma, self.box, origins, dirs, self.finest_mm / 8)


def blob_sum(centres: np.ndarray, widths: np.ndarray, amplitudes: np.ndarray) -> Callable:
    """sigma(p) = sum_k a_k exp(-|p - c_k|^2 / (2 w_k^2))."""
    c, w, a = (torch.as_tensor(np.asarray(x, np.float64)) for x in (centres, widths, amplitudes))

    def sigma(p: torch.Tensor) -> torch.Tensor:
        shape, flat, n = p.shape[:-1], p.reshape(-1, 3), 8192  # (n, blobs, 3) a few MB at a time: 2x faster on a box
        parts = []
        for i in range(0, max(len(flat), 1), n):
            q = flat[i:i + n, None] - c
            parts.append((a * torch.exp(-(q * q).sum(-1) / (2 * w * w))).sum(-1))
        return torch.cat(parts).reshape(shape)

    return sigma


def _blob_flame(name: str, box: ProbeBox, c, w, a, peak: float) -> Flame:
    with torch.no_grad():
        lo = float(blob_sum(c, w, a)(torch.as_tensor(box.centres(), dtype=torch.float64)).min())
    a = np.asarray(a) * (peak / -lo)
    return Flame(blob_sum(c, w, a), box, name, float(np.min(w)), (np.asarray(c), np.asarray(w), a))


def plumes(seed: int) -> Flame:
    """Two or three plumes rising through a 60 x 100 x 60 mm box: chains of 10 blobs along helices (radius 2-6 mm,
    0.5-1.5 turns), 4-7 mm wide at the bottom and 1.5x wider at the top; the hottest point at 1800 K."""
    rng = np.random.default_rng(seed)
    box = ProbeBox((60, 100, 60), 1.0)
    c, w, a = [], [], []
    for _ in range(int(rng.integers(2, 4))):
        x0, z0 = rng.uniform(-5, 5, 2)
        radius, turns, phase = rng.uniform(2, 6), rng.uniform(0.5, 1.5), rng.uniform(0, 2 * np.pi)
        w0, strength = rng.uniform(4, 7), rng.uniform(0.5, 1.0)
        for y in np.linspace(-40, 40, 10):
            th = phase + 2 * np.pi * turns * (y + 40) / 80
            c.append([x0 + radius * np.cos(th), y, z0 + radius * np.sin(th)])
            w.append(w0 * (1 + 0.5 * (y + 40) / 80))
            a.append(-strength * rng.uniform(0.7, 1.0))
    return _blob_flame(f"plumes-{seed}", box, c, w, a, AMBIENT.sigma_from_temperature(1800.0) * -1)


def eddies(seed: int) -> Flame:
    """40 blobs of 1-6 mm (log-uniform width, amplitude growing with width) in a cone widening from 6 to 20 mm
    radius up a 60 x 100 x 60 mm box; the hottest point at 1800 K."""
    rng = np.random.default_rng(seed)
    box = ProbeBox((60, 100, 60), 1.0)
    n = 40
    y = rng.uniform(-40, 40, n)
    r = (6 + 14 * (y + 40) / 80) * np.sqrt(rng.uniform(0, 1, n))
    th = rng.uniform(0, 2 * np.pi, n)
    c = np.stack([r * np.cos(th), y, r * np.sin(th)], -1)
    w = np.exp(rng.uniform(np.log(1.0), np.log(6.0), n))
    a = -(w / 6.0) ** 0.5 * rng.uniform(0.5, 1.0, n)
    return _blob_flame(f"eddies-{seed}", box, c, w, a, AMBIENT.sigma_from_temperature(1800.0) * -1)


def _temperature_flame(T: Callable, box: ProbeBox, name: str, finest_mm: float) -> Flame:
    return Flame(lambda p: AMBIENT.sigma_from_temperature(T(p)), box, name, finest_mm)


def phantom5(seed: int) -> Flame:
    """The paper's Phantom 5 (rises of 1196.85 K and 696.85 K over 300 K) on its own 72 x 100 x 72 mm box; the
    seed turns it about the vertical axis (seed x 17 degrees)."""
    rot = math.radians(17.0 * seed)
    cs, sn = math.cos(rot), math.sin(rot)

    def T(p):
        x, y, z = p[..., 0] * cs - p[..., 2] * sn, p[..., 1], p[..., 0] * sn + p[..., 2] * cs
        return phantom5_temperature(x, y, z, AMBIENT.T0, exp=torch.exp)

    return _temperature_flame(T, ProbeBox((72, 100, 72), 1.0), f"phantom5-{seed}", 4.0)


def axisymmetric(seed: int) -> Flame:
    """The lifted-jet flame (peak 1800 K) on a 72 x 100 x 72 mm box, its lift height moved by the seed (-30 mm
    and 6 mm higher per seed)."""
    def T(p):
        r = torch.sqrt(p[..., 0] ** 2 + p[..., 2] ** 2 + 1e-12)
        return lifted_jet_profile(r, p[..., 1], AMBIENT.T0, 1800.0, lift_mm=-30.0 + 6.0 * seed, exp=torch.exp,
                                  tanh=torch.tanh, clip=torch.clamp)

    return _temperature_flame(T, ProbeBox((72, 100, 72), 1.0), f"axisymmetric-{seed}", 4.0)


def turbulent(seed: int) -> Flame:
    """A plume whose radius grows from 8 to 15 mm up a 60 x 100 x 60 mm box (peak rise 1000 K) times
    ``exp(0.35 F - 0.35^2 / 2)``, F a unit-variance sum of 48 random Fourier modes of 4-40 mm wavelength with a
    -5/3 energy spectrum."""
    rng = np.random.default_rng(seed)
    box = ProbeBox((60, 100, 60), 1.0)
    n = 48
    lam = np.exp(rng.uniform(np.log(4.0), np.log(40.0), n))  # log-uniform wavelengths: density 1/k per mode
    k = 2 * np.pi / lam
    amp = k ** (-5.0 / 6.0 + 0.5)  # energy k^(-5/3) per unit k: amplitude^2 * (1/k density) ~ k^(-5/3) dk
    amp /= np.sqrt((amp**2).sum() / 2)
    dirs = rng.standard_normal((n, 3))
    kv = torch.as_tensor(dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * k[:, None])
    phase, amp = torch.as_tensor(rng.uniform(0, 2 * np.pi, n)), torch.as_tensor(amp)

    def T(p):
        r2 = p[..., 0] ** 2 + p[..., 2] ** 2
        R = 8.0 + 7.0 * (p[..., 1] + 50) / 100
        envelope = torch.exp(-0.5 * r2 / R**2) * (8.0 / R) * 0.5 * (1 + torch.tanh((p[..., 1] + 42) / 3))
        F = (amp * torch.cos(p @ kv.T + phase)).sum(-1)
        return AMBIENT.T0 + 1000.0 * envelope * torch.exp(0.35 * F - 0.35**2 / 2)

    return _temperature_flame(T, box, f"turbulent-{seed}", 4.0)  # the shortest wavelength


FAMILIES = {"plumes": plumes, "eddies": eddies, "phantom5": phantom5, "axisymmetric": axisymmetric,
            "turbulent": turbulent}


def render(sigma: Callable, box: ProbeBox, origins: torch.Tensor, dirs: torch.Tensor, step_mm: float,
           chunk: int = 4096) -> tuple[torch.Tensor, torch.Tensor]:
    """Deflections and path integrals of sigma along straight rays through ``box``, by composite Simpson
    quadrature (step at most ``step_mm``) of sigma and of its autograd gradient.

    Args:
        origins, dirs: (R, 3) [mm] and unit vectors (float64).
    Returns:
        eps: (R, 3) integral of grad sigma ds (dimensionless: deflections of sigma); zero for rays that miss the box.
        path: (R,) integral of sigma ds [mm].
    """
    eps, path = torch.zeros_like(dirs), torch.zeros(len(dirs), dtype=dirs.dtype)
    t0, t1, hit = box.intersect(origins, dirs)
    n = 2 * max(1, math.ceil(float((t1 - t0).clamp_min(0).max()) / step_mm / 2))  # even number of intervals
    weights = torch.ones(n + 1, dtype=dirs.dtype)
    weights[1:-1:2], weights[2:-1:2] = 4.0, 2.0
    for s in torch.nonzero(hit).squeeze(1).split(chunk):
        h = (t1[s] - t0[s]) / n
        t = t0[s, None] + h[:, None] * torch.arange(n + 1, dtype=dirs.dtype)
        p = (origins[s, None] + t[..., None] * dirs[s, None]).requires_grad_(True)
        f = sigma(p)
        (g,) = torch.autograd.grad(f.sum(), p)
        w = weights * h[:, None] / 3
        eps[s] = (w[..., None] * g).sum(1)
        path[s] = (w * f.detach()).sum(1)
    return eps, path


def blob_deflection(centres: np.ndarray, widths: np.ndarray, amplitudes: np.ndarray, box: ProbeBox,
                    origins: torch.Tensor, dirs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Closed-form integrals of grad sigma and of sigma along rays over their chord through ``box``, for a sum of
    Gaussian blobs (:func:`blob_sum`). With q the offset of the blob centre from the ray and tau the centre's
    position along it, a blob's path integral is ``P = a exp(-|q|^2 / 2w^2) w sqrt(pi/2) [erf((t + tau) /
    (w sqrt 2))]_t0^t1``; the part of its deflection perpendicular to the ray is ``-q / w^2 P``, the part along
    the ray ``sigma(t1) - sigma(t0)``. origins, dirs (R, 3) float64 -> eps (R, 3), path (R,) [mm]."""
    t0, t1, hit = box.intersect(origins, dirs)
    t1 = torch.where(hit, t1, t0)
    out, path = torch.zeros_like(dirs), torch.zeros(len(dirs), dtype=dirs.dtype)
    for c, w, a in zip(*(np.asarray(x, np.float64) for x in (centres, widths, amplitudes))):
        rel = origins - torch.as_tensor(c)
        tau = (rel * dirs).sum(-1)
        q = rel - tau[:, None] * dirs
        g = a * torch.exp(-(q * q).sum(-1) / (2 * w * w))
        erf = torch.erf((t1 + tau) / (w * math.sqrt(2))) - torch.erf((t0 + tau) / (w * math.sqrt(2)))
        P = g * w * math.sqrt(math.pi / 2) * erf
        along = g * (torch.exp(-(t1 + tau) ** 2 / (2 * w * w)) - torch.exp(-(t0 + tau) ** 2 / (2 * w * w)))
        out += -q / (w * w) * P[:, None] + along[:, None] * dirs
        path += P
    return out, path


def write_dataset(root, flame: Flame, noise: float = 0.0, noise_seed: int = 0, n_views: int = 9,
                  span_deg: float = 162.0, heldout_deg=(10.125, 91.125), binning: int = 4) -> list[str]:
    """Render ``flame`` for a rig of ``n_views`` cameras over ``span_deg`` (the arc rig's 720 x 1280 sensor at
    ``binning``: 180 x 320 px by default) plus held-out cameras at ``heldout_deg``, and write it in the paper's
    format (:func:`nerif.data.transforms.write_split`; splits train and val) with the true temperature
    (``truth_T.npy``).

    Every pixel's ray is rendered thin, through the pixel centre. ``noise``: Gaussian deflection noise, its RMS
    magnitude that fraction of the RMS deflection of the rays that cross the box, perpendicular to each ray.
    2-D masks: pixels whose path integral of sigma exceeds 1 % of the largest, dilated by 2 px.

    Returns the overrides that reconstruct it: ``python -m nerif <overrides>``.
    """
    root = Path(root)
    angles = {"train": list(np.linspace(0.0, span_deg, n_views)), "val": list(heldout_deg)}
    cams = {s: arc_rig(angles_deg=a, binning=binning) for s, a in angles.items()}
    rendered = {}
    for split, cameras in cams.items():
        o, d, pixel, start = rays_in_box(flame.box, cameras)
        d = d.double()
        eps, path = flame.render(o.double()[view_index(start)], d)
        if noise > 0:
            eps = with_noise(eps, d, noise, noise_seed + (split == "val"))
        rendered[split] = perpendicular(eps, d), path, pixel, start
    largest = max(float(r[1].abs().max()) for r in rendered.values())
    for split, (eps, path, pixel, start) in rendered.items():
        eps_images, masks = [], []
        for v, cam in enumerate(cams[split]):
            s = slice(int(start[v]), int(start[v + 1]))
            img, p = np.zeros((cam.height * cam.width, 3)), np.zeros(cam.height * cam.width)
            img[pixel[s].numpy()], p[pixel[s].numpy()] = eps[s].numpy(), path[s].abs().numpy()
            eps_images.append(img.reshape(cam.height, cam.width, 3))
            mask = (p.reshape(cam.height, cam.width) > 0.01 * largest).astype(np.uint8)
            masks.append(cv2.dilate(mask, np.ones((5, 5), np.uint8)) > 0)
        write_split(root, split, cams[split], eps_images, masks)
    truth = flame.truth_T()
    atomic_write(root / "truth_T.npy", lambda t: np.save(open(t, "wb"), truth))
    cam = cams["train"][0]
    return ["data=transforms", f"data.root={root}", f"data.probe.shape=[{','.join(map(str, flame.box.shape))}]",
            f"data.probe.voxel_mm={flame.box.voxel_mm}", f"data.T0={AMBIENT.T0}", f"data.n0={AMBIENT.n0}",
            f"data.T_max={AMBIENT.T_max}", f"data.pitch_um={cam.pitch_mm * 1e3:g}",
            f"data.truth={root / 'truth_T.npy'}"]
