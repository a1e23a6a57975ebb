"""Each view's observation model on the image grid: units converted in one place, the shake, the blocks of pixels."""

import pytest
import torch

from nerif.configs import group
from nerif.data import DATASETS
from nerif.data.observation import observations
from nerif.sensing.imaging import warp
from nerif.sensing.interpolation import interpolation
from tests.helpers import tiny_config

REALISTIC = ("data.sensing=realistic", "data.sensor.aperture_rays=1", "data.sensor.image_binning=4",
             "phantom.width_mm=9.0", "data.sensor.noise_variance=0")


@pytest.fixture(scope="module")
def scene():
    return DATASETS.build(group(tiny_config(*REALISTIC), "data"))


def test_a_fields_deflections_become_the_displacements_the_images_hold(scene):
    """The model's displacement of the true deflections, in image pixels, moves the reference onto the distorted
    image: the photometric residual at the true field is far below the one at no field (an independent check of
    the units: a factor of the binning off would leave most of it). The rays picked by ``rows`` get their own rows of
    the whole view's."""
    for view in observations(scene)[:2]:
        b = view.block
        u = view.displacement(scene.observed[view.rays])  # (n, 2) image px, the shake in
        rows = torch.tensor([3, 0, len(u) - 1])
        assert torch.equal(view.displacement(scene.observed[view.rays][rows], rows), u[rows])
        x = view.pixels().double()  # (n, b^2, 2)
        assert x.shape == (len(u), b * b, 2)
        ref, dist = view.reference.double(), view.distorted.double()
        field = torch.zeros(ref.shape + (2,), dtype=torch.float64)
        xi = x.reshape(-1, 2).long()
        field[xi[:, 1], xi[:, 0]] = u[:, None, :].expand(-1, b * b, -1).reshape(-1, 2)
        seen, held = warp(ref, field), torch.zeros(ref.shape, dtype=torch.bool)
        held[xi[:, 1], xi[:, 0]] = True
        moving = held & (field.norm(dim=-1) > 0.3 * float(field.norm(dim=-1).max()))
        assert int(moving.sum()) > 50 and float(field.norm(dim=-1).max()) > 0.1
        at_truth = (seen - dist)[moving].pow(2).mean().sqrt()
        at_none = (ref - dist)[moving].pow(2).mean().sqrt()
        assert float(at_truth) < 0.6 * float(at_none), (float(at_truth), float(at_none))
        # the view's own residual, read by a registered interpolation, says the same of the same pixels
        for read in (interpolation("bicubic"), interpolation("bandlimited")):
            images = view.images(read)
            r_truth, r_none = view.residual(u, read, images), view.residual(torch.zeros_like(u), read, images)
            assert r_truth.shape == (len(u), b * b)
            sel = moving[xi[:, 1], xi[:, 0]].reshape(len(u), b * b)
            ratio = float(r_truth[sel].pow(2).mean().sqrt() / r_none[sel].pow(2).mean().sqrt())
            assert ratio < 0.7, ratio


def test_units_and_the_shake_convert_in_one_place(scene):
    """Full-sensor and image pixels differ by the images' binning both ways; the shake the measurement took off
    (full-sensor px) is held in image px; the gain per unit of sigma is the scene's per radian times its scale."""
    shaken = scene.with_found(shake_px=[[0.8 * v, -0.4] for v in range(scene.n_views)])
    for view in observations(shaken):
        binning = shaken.images[view.view].camera.binning
        assert binning == 4 and view.block == shaken.image_block()
        torch.testing.assert_close(view.shake_px, torch.tensor([0.8 * view.view, -0.4], dtype=torch.float64) / 4)
        u = torch.tensor([[2.0, -6.0]], dtype=torch.float64)
        torch.testing.assert_close(view.sensor_px(view.image_px(u)), u)
        eps = shaken.eps[view.rays][:5].double()
        torch.testing.assert_close((view.gain_px[:5] @ (eps / shaken.scale)[..., None])[..., 0],
                                   view.image_px(shaken.to_displacement(eps, torch.arange(view.rays.start,
                                                                                          view.rays.start + 5))))
