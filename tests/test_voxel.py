"""Voxel forward model against closed forms and conservation facts."""
import numpy as np
import pytest
import torch

from nerif.data.phantoms import gaussian_blob, gaussian_blob_deflection
from nerif.geometry import rays_in_box
from nerif.geometry import ProbeBox, arc_rig
from nerif.renderers import gradient_volume, voxel_deflection


def _rays(box, n_cameras=4, binning=16):
    o, d, _, vs = rays_in_box(box, arc_rig(n_cameras=n_cameras, binning=binning))
    return o[torch.repeat_interleave(torch.arange(n_cameras), vs.diff())].double(), d.double()


def test_gaussian_blob_deflection_matches_closed_form():
    # box half-width 28.8 mm = 4.6 widths from the off-centre blob: truncation is negligible
    ph = gaussian_blob(shape=(64, 64, 64), voxel_mm=0.9, width_mm=6.0, centre_mm=(1.5, -1.0, 0.5))
    o, d = _rays(ph.box)
    eps = voxel_deflection(torch.as_tensor(ph.delta), ph.box, o, d)
    ref = gaussian_blob_deflection(o, d, (1.5, -1.0, 0.5), 6.0, float(ph.delta.min()))
    sees = ref.norm(dim=-1) > 0.01 * ref.norm(dim=-1).max()
    assert sees.sum() > 100
    rel = ((eps - ref)[sees].norm() / ref[sees].norm()).item()
    assert rel < 0.01, rel
    assert ref.abs().max() > 1e-4  # a flame-like 1e-4 rad signal


def test_deflection_along_the_ray_vanishes_for_a_bounded_field():
    ph = gaussian_blob(shape=(40, 40, 40), voxel_mm=1.5, width_mm=7.0)
    o, d = _rays(ph.box, n_cameras=3)
    eps = voxel_deflection(torch.as_tensor(ph.delta), ph.box, o, d)
    along = (eps * d).sum(-1).abs()
    # exactly zero for the continuous field; the grid's central differences leave a discretisation residue
    assert along.max() < 1e-2 * eps.norm(dim=-1).max()
    assert along.mean() < 1e-3 * eps.norm(dim=-1).max()


def test_rays_along_z_see_no_z_deflection_through_a_bounded_field():
    ph = gaussian_blob(shape=(40, 40, 40), voxel_mm=1.0, width_mm=3.0, centre_mm=(1.0, 0.5, -2.0))
    box, delta = ph.box, torch.as_tensor(ph.delta)
    xy = torch.rand(50, 2, dtype=torch.float64) * 8 - 4
    o = torch.cat([xy, torch.full((50, 1), 50.0, dtype=torch.float64)], 1)
    d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64).expand(50, 3)
    eps = voxel_deflection(delta, box, o, d, step_mm=0.05)
    assert eps[:, 2].abs().max() < 1e-4 * eps[:, :2].abs().max()


def test_gradient_volume_is_exact_for_a_linear_field_up_to_the_faces():
    box = ProbeBox((6, 5, 4), 2.0)
    c = torch.as_tensor(box.centres())
    g = gradient_volume(3 * c[..., 0] - 2 * c[..., 2], box.voxel_mm)
    torch.testing.assert_close(g, torch.stack([torch.full_like(g[0], 3.0), torch.zeros_like(g[0]),
                                               torch.full_like(g[0], -2.0)]))


def test_a_linear_field_deflects_every_ray_by_its_gradient_times_the_chord():
    box = ProbeBox((10, 12, 10), 1.0)
    c = torch.as_tensor(box.centres())
    o, d = _rays(box, n_cameras=3, binning=40)
    eps = voxel_deflection(0.5 * c[..., 0] + 0.25 * c[..., 1], box, o, d)
    t0, t1, _ = box.intersect(o, d)
    torch.testing.assert_close(eps, (t1 - t0)[:, None] * torch.tensor([0.5, 0.25, 0.0], dtype=torch.float64))


def test_voxel_deflection_is_linear_with_an_exact_adjoint():
    box = ProbeBox((10, 12, 10), 1.0)
    o, d = _rays(box, n_cameras=2, binning=40)
    x = torch.randn(10, 12, 10, dtype=torch.float64)
    y = torch.randn(len(d), 3, dtype=torch.float64)
    A = lambda v: voxel_deflection(v, box, o, d)  # noqa: E731
    _, vjp = torch.func.vjp(A, x)
    (ATy,) = vjp(y)
    lhs, rhs = (A(x) * y).sum().item(), (x * ATy).sum().item()
    assert lhs == pytest.approx(rhs, rel=1e-10)
    torch.testing.assert_close(A(2 * x + 1e-3 * ATy), 2 * A(x) + 1e-3 * A(ATy))


def test_rays_missing_the_box_deflect_nothing():
    box = ProbeBox((10, 10, 10), 1.0)
    o = torch.tensor([[100.0, 0.0, 100.0]], dtype=torch.float64)
    d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)
    assert voxel_deflection(torch.ones(10, 10, 10, dtype=torch.float64), box, o, d).abs().max() == 0
    assert np.isfinite(voxel_deflection(torch.ones(10, 10, 10, dtype=torch.float64), box, o, d).numpy()).all()
