"""Gradient operators: autograd and central differences against closed forms and each other."""
import pytest
import torch

from nerif.encoders import ENCODERS
from nerif.field import NeuralField
from nerif.geometry import ProbeBox
from nerif.renderers import GRADIENTS

BOX = ProbeBox((20, 30, 20), 1.0)


def _smooth(p):
    return torch.exp(-(p**2).sum(-1) / 50.0) * torch.sin(0.3 * p[:, 0] + 0.1 * p[:, 1] * p[:, 2])


def _smooth_gradient(p):
    x, y, z = p.unbind(-1)
    e, s, c = torch.exp(-(p**2).sum(-1) / 50.0), torch.sin(0.3 * x + 0.1 * y * z), torch.cos(0.3 * x + 0.1 * y * z)
    return torch.stack([e * (-x / 25 * s + 0.3 * c), e * (-y / 25 * s + 0.1 * z * c), e * (-z / 25 * s + 0.1 * y * c)], -1)


def test_auto_and_discrete_gradients_agree_on_a_smooth_field():
    p = torch.rand(300, 3, dtype=torch.float64) * 16 - 8
    ga = GRADIENTS.get("auto")(_smooth, p, create_graph=False, step_mm=0.0)
    gd = GRADIENTS.get("discrete")(_smooth, p, create_graph=False, step_mm=1e-3)
    torch.testing.assert_close(ga, _smooth_gradient(p))
    torch.testing.assert_close(gd, ga, rtol=1e-5, atol=1e-7)
    # central differences are second order: the error drops 4x when the step halves
    e1 = (GRADIENTS.get("discrete")(_smooth, p, create_graph=False, step_mm=0.2) - ga).abs().max()
    e2 = (GRADIENTS.get("discrete")(_smooth, p, create_graph=False, step_mm=0.1) - ga).abs().max()
    assert 3.5 < (e1 / e2).item() < 4.5


def test_auto_and_discrete_agree_on_a_trained_shape_network():
    """On a network field the two agree except where the step straddles a LeakyReLU kink."""
    field = NeuralField(ENCODERS.build({"name": "frequency", "n_octaves": 3}), BOX).double()
    with torch.no_grad():
        for prm in field.mlp.parameters():
            prm.normal_(0, 0.3)
    p = torch.rand(400, 3, dtype=torch.float64) * 16 - 8
    ga = GRADIENTS.get("auto")(field, p, create_graph=False, step_mm=0.0)
    gd = GRADIENTS.get("discrete")(field, p, create_graph=False, step_mm=1e-4)
    close = ((gd - ga).norm(dim=-1) < 1e-4 * ga.norm(dim=-1).max())
    assert close.float().mean() > 0.9


def test_gradients_are_per_millimetre_through_the_normalisation():
    # sigma linear in the network coordinate x / scale_mm: d sigma / dx = w / scale_mm per mm
    field = NeuralField(ENCODERS.build({"name": "none"}), BOX, hidden=()).double()
    with torch.no_grad():
        field.mlp[-1].weight.copy_(torch.tensor([[1e-3, 0.0, 0.0]]))
    p = torch.zeros(1, 3, dtype=torch.float64)
    g = GRADIENTS.get("auto")(field, p, create_graph=False, step_mm=0.0)
    # sigma = k tanh(w x / s + b) + c with tanh(b) = -c / k at p = 0
    slope = field.k * (1 - (field.c / field.k) ** 2) * 1e-3 / BOX.scale_mm
    assert g[0, 0].item() == pytest.approx(slope, rel=1e-9)
    assert g[0, 1:].abs().max() == 0


def _perpendicular(g, d):
    return g - (g * d).sum(-1, keepdim=True) * d


def test_discrete_across_the_ray_is_the_perpendicular_part_of_the_full_gradient():
    """With ray directions, ``discrete`` differences along two directions across each ray (4 evaluations):
    exact, as the 6-evaluation reference is, on a quadratic field; second order on a smooth one."""
    p = torch.rand(500, 3, dtype=torch.float64) * 16 - 8
    d = torch.nn.functional.normalize(torch.randn(500, 3, dtype=torch.float64), dim=-1)
    d[:3] = torch.eye(3, dtype=torch.float64)  # rays along the axes too
    a = torch.randn(3, 3, dtype=torch.float64)

    def quadratic(q):
        return ((q @ a) * q).sum(-1) + q[:, 0] - 2 * q[:, 2]

    discrete = GRADIENTS.get("discrete")
    full = discrete(quadratic, p, create_graph=False, step_mm=0.3)
    fast = discrete(quadratic, p, create_graph=False, step_mm=0.3, across=d)
    torch.testing.assert_close(fast, _perpendicular(full, d), rtol=1e-10, atol=1e-10)
    assert (fast * d).sum(-1).abs().max() < 1e-10
    exact = _perpendicular(_smooth_gradient(p), d)
    e1 = (discrete(_smooth, p, create_graph=False, step_mm=0.2, across=d) - exact).abs().max()
    e2 = (discrete(_smooth, p, create_graph=False, step_mm=0.1, across=d) - exact).abs().max()
    assert 3.5 < (e1 / e2).item() < 4.5
