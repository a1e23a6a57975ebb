import pytest
import torch

from nerif.encoders import ENCODERS
from nerif.field import NeuralField
from nerif.geometry import ProbeBox
from nerif.losses import AmbientBoundary, TotalVariation, deflection_mse

BOX = ProbeBox((10, 20, 16), 1.0)


def test_boundary_points_lie_on_the_chosen_faces():
    cond = AmbientBoundary(BOX, faces=("x", "z"), points=2000)
    p = cond.sample(torch.Generator().manual_seed(0), "cpu")
    half = torch.as_tensor(BOX.half_mm, dtype=torch.float32)
    on_face = (p.abs() - half).abs() < 1e-5  # (N, 3)
    assert bool((on_face[:, 0] | on_face[:, 2]).all()) and not bool(on_face[:, 1].any())
    assert bool((p.abs() <= half + 1e-5).all())
    # both faces of both axes are used
    assert {(int(torch.sign(q[0])) if f[0] else 0, int(torch.sign(q[2])) if f[2] else 0)
            for q, f in zip(p, on_face)} >= {(1, 0), (-1, 0), (0, 1), (0, -1)}


def test_boundary_loss_measures_a_constant_offset():
    field = NeuralField(ENCODERS.build({"name": "none"}), BOX, prior=(-1.0, 1.0))
    with torch.no_grad():
        field.mlp[-1].bias.fill_(float(torch.atanh(torch.tensor(0.2))))  # sigma = 0.2 everywhere
    assert AmbientBoundary(BOX, weight=0.5)(field).item() == pytest.approx(0.5 * 0.2, rel=1e-5)
    assert not AmbientBoundary(BOX, faces=()).active
    with pytest.raises(ValueError, match="ambient faces"):
        AmbientBoundary(BOX, faces=("w",))


def test_deflection_mse_weights_the_terms():
    obs = torch.zeros(4, 3)
    eps = {"auto": torch.ones(4, 3), "discrete": 2 * torch.ones(4, 3)}
    assert deflection_mse(eps, obs, {"auto": 1.0, "discrete": 0.0}).item() == pytest.approx(3.0)
    assert deflection_mse(eps, obs, {"auto": 0.5, "discrete": 1.0}).item() == pytest.approx(1.5 + 12.0)
    with pytest.raises(ValueError, match="nothing to train on"):
        deflection_mse(eps, obs, {"auto": 0.0, "discrete": 0.0})


class _Linear(torch.nn.Module):
    """sigma = g . p: |grad sigma| = |g| everywhere."""

    def __init__(self, g):
        super().__init__()
        self.g = torch.nn.Parameter(torch.as_tensor(g, dtype=torch.float32))

    def forward(self, p):
        return p @ self.g


def test_total_variation_of_a_linear_field():
    """A linear field's forward differences are exact: the term is weight * s * h * |g| (+ the tiny eps)."""
    box = ProbeBox((10, 20, 16), 0.5)
    tv = TotalVariation(box, weight=0.3, points=64, scale=2.0, eps=1e-6)
    field = _Linear([0.3, -0.4, 1.2])
    assert tv(field, torch.Generator().manual_seed(0)).item() == pytest.approx(0.3 * 2.0 * 0.5 * 1.3, rel=1e-5)
    # a constant has none, and its weight scales with the deflections (sigma -> c sigma: c^2, like the misfit)
    assert tv(_Linear([0.0, 0.0, 0.0])).item() == pytest.approx(0.0, abs=1e-5)
    big = TotalVariation(box, weight=0.3, points=64, scale=6.0, eps=1e-6)
    assert big(_Linear([0.9, -1.2, 3.6])).item() == pytest.approx(9 * tv(field).item(), rel=1e-5)
    assert not TotalVariation(box, weight=0.0, points=64, scale=1.0).active
    with pytest.raises(ValueError, match="cannot be negative"):
        TotalVariation(box, weight=-1.0, points=64, scale=1.0)
