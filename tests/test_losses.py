import pytest
import torch

from nerif.encoders import ENCODERS
from nerif.field import NeuralField
from nerif.geometry import ProbeBox
from nerif.losses import AmbientBoundary, deflection_mse

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
