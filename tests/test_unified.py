"""Unified BOS (solver=cgls data_term=images): the operator's adjoint, and its two rows per ray against every
pixel's own equation."""
import pytest
import torch

from nerif.configs import group
from nerif.data import DATASETS
from nerif.losses.images import bandpass, block_pixels
from nerif.sensing.displacement import displacement_matrix
from nerif.sensing.interpolation import interpolation, sample
from nerif.solvers.voxel.unified import unified_system
from tests.helpers import solver, tiny_config

REALISTIC = ("data.sensing=realistic", "data.sensor.aperture_rays=1", "data.sensor.image_binning=4",
             "phantom.width_mm=9.0", "data.sensor.noise_variance=1e-4")


@pytest.fixture(scope="module")
def scene():
    return DATASETS.build(group(tiny_config(*REALISTIC), "data"))


@pytest.mark.parametrize("linearize_at", ["zero", "flow"])
def test_the_unified_operator_passes_the_adjoint_identity(scene, linearize_at):
    cfg = tiny_config(*REALISTIC, "solver=cgls", "data_term=images", f"solver.linearize_at={linearize_at}",
                      "solver.dtype=float64")
    s = solver(cfg, scene)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(scene.box.shape, generator=g, dtype=torch.float64)
    y = torch.randn(s.cgls.b.shape, generator=g, dtype=torch.float64)
    assert s.cgls.b.shape == (len(scene.dirs), 2)  # two rows per ray
    lhs, rhs = float((s.cgls._A(x) * y).sum()), float((x * s.cgls._At(y)).sum())
    assert lhs == pytest.approx(rhs, rel=1e-10)


def test_two_rows_per_ray_are_the_least_squares_of_every_pixel_of_its_block(scene):
    """sum over the block's pixels of (g . u - (I_dist - I_ref))^2 = |M eps - c|^2 + const for any eps: the
    difference between two deflections' costs is the same computed either way."""
    M, c = unified_system(scene, 8.0, "zero", deflection_units=False, read=interpolation("bicubic"))
    v, cam, im = 1, scene.cameras[1], scene.images[1]
    b = cam.binning // im.camera.binning
    sl = scene.view_slice(v)
    rays = torch.arange(sl.start, sl.stop)[::7][:12]
    A = displacement_matrix(scene.dirs[rays].double(), im.camera) * scene.scale
    ref, dist = (bandpass(i.double(), 8.0) for i in (im.reference, im.distorted))
    x = block_pixels(scene.pixel[rays], cam.width, b).double()
    shift = scene.shake_px()[v] / im.camera.binning  # the view's measured shake: the images hold it
    h = 0.01  # the interpolant's gradient, by the central differences unified_system takes
    xs = x + shift
    gx = (sample(ref, (xs + torch.tensor([h, 0.0])).reshape(-1, 2)) - sample(ref, (xs - torch.tensor([h, 0.0])).reshape(-1, 2))) / (2 * h)
    gy = (sample(ref, (xs + torch.tensor([0.0, h])).reshape(-1, 2)) - sample(ref, (xs - torch.tensor([0.0, h])).reshape(-1, 2))) / (2 * h)
    grad = torch.stack([gx, gy], -1).reshape(len(rays), -1, 2)
    xi = x.reshape(-1, 2).long()
    diff = (dist[xi[:, 1], xi[:, 0]] - sample(ref, xs.reshape(-1, 2))).reshape(len(rays), -1)
    gen = torch.Generator().manual_seed(1)
    e1, e2 = (0.05 * torch.randn(len(rays), 3, generator=gen, dtype=torch.float64) for _ in range(2))

    def per_pixel(e):
        u = (A @ e[..., None])[..., 0]
        return ((grad * u[:, None, :]).sum(-1) - diff).pow(2).sum(-1)

    def rows(e):
        return ((M[rays] @ e[..., None])[..., 0] - c[rays]).pow(2).sum(-1)

    torch.testing.assert_close(rows(e1) - rows(e2), per_pixel(e1) - per_pixel(e2), rtol=1e-5, atol=1e-9)


def test_the_default_data_term_is_two_step_for_the_voxel_solver(scene):
    """``data_term=auto`` fits the images for the neural solver but the flow's deflections for CGLS (two-step,
    measured better than unified on the independent capture): three components per ray, not two rows."""
    s = solver(tiny_config(*REALISTIC, "solver=cgls"), scene)
    assert s.cgls.b.shape == (len(scene.dirs), 3) and "data_term" not in s.labels
    s = solver(tiny_config(*REALISTIC, "solver=cgls", "data_term=images"), scene)
    assert s.cgls.b.shape == (len(scene.dirs), 2) and s.labels["data_term"] == "images"


def test_the_rows_weigh_a_deflection_as_the_flows_rows_do(scene):
    """In deflection units, a change of the deflections perpendicular to the rays changes the squared residual of
    the two rows by about its own squared size (the flow's rows: exactly), so that ``solver.lam`` weighs the same
    for both."""
    d = torch.randn(len(scene.dirs), 3, generator=torch.Generator().manual_seed(2), dtype=torch.float64)
    dirs = scene.dirs.double()
    d = d - (d * dirs).sum(-1, keepdim=True) * dirs

    def worth(M):
        return float((M @ d[..., None]).pow(2).sum((-1, -2)).mean() / d.pow(2).sum(-1).mean())

    assert 0.5 < worth(unified_system(scene, 8.0, "zero", read=interpolation("bandlimited"))[0]) < 2.0
