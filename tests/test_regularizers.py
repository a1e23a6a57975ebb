"""The terms on the field itself (nerif.losses.regularizers), against closed forms on fields whose values are known
everywhere: the ambient condition reads the field on the named faces only, total variation is a linear field's
gradient over one voxel."""
import math

import pytest
import torch

from nerif.geometry import ProbeBox
from nerif.losses.regularizers import AmbientBoundary, TotalVariation


class Linear(torch.nn.Module):
    """sigma(p) = a . p + c [p in mm]: a field whose gradient and face values are known in closed form."""

    def __init__(self, a, c=0.0):
        super().__init__()
        self.a = torch.nn.Parameter(torch.tensor(a, dtype=torch.float32))
        self.c = float(c)

    def forward(self, p):
        return p @ self.a + self.c


BOX = ProbeBox((10, 20, 30), 0.5)  # half extents 2.5, 5, 7.5 mm


def value(term, field, seed=0) -> float:
    return float(term(field, torch.Generator().manual_seed(seed)).detach())


@pytest.mark.parametrize("faces, axis, side", [(["-x"], 0, -1), (["+y"], 1, 1), (["+z"], 2, 1)])
def test_the_ambient_points_lie_on_the_named_face_and_cover_it(faces, axis, side):
    term = AmbientBoundary(BOX, faces, weight=1.0, points=4000)
    p = term.sample(torch.Generator().manual_seed(0), "cpu")
    half = torch.tensor(BOX.half_mm, dtype=p.dtype)
    assert torch.allclose(p[:, axis], torch.full_like(p[:, axis], side * float(half[axis])))
    others = [k for k in range(3) if k != axis]
    # uniform on the face: each other coordinate's mean 0 and its variance half^2 / 3
    for k in others:
        assert abs(float(p[:, k].mean())) < 0.05 * float(half[k])
        assert float(p[:, k].var()) == pytest.approx(float(half[k]) ** 2 / 3, rel=0.08)
        assert float(p[:, k].abs().max()) <= float(half[k]) + 1e-5


def test_both_faces_of_an_axis_are_drawn_evenly():
    p = AmbientBoundary(BOX, ["x"], weight=1.0, points=4000).sample(torch.Generator().manual_seed(1), "cpu")
    plus = float((p[:, 0] > 0).float().mean())
    assert abs(plus - 0.5) < 0.03  # 4000 draws: 0.8 % standard error
    assert torch.allclose(p[:, 0].abs(), torch.full_like(p[:, 0], 2.5))


def test_the_ambient_term_is_the_mean_magnitude_on_the_faces():
    """sigma = x + 1 on the +x face (x = 2.5) is 3.5 everywhere; on the -x face -1.5: |.| means 3.5 and 1.5."""
    field = Linear([1.0, 0.0, 0.0], c=1.0)
    assert value(AmbientBoundary(BOX, ["+x"], weight=0.2, points=64), field) == pytest.approx(0.2 * 3.5, rel=1e-5)
    assert value(AmbientBoundary(BOX, ["-x"], weight=0.2, points=64), field) == pytest.approx(0.2 * 1.5, rel=1e-5)
    both = value(AmbientBoundary(BOX, ["x"], weight=1.0, points=20000), field, 2)
    assert both == pytest.approx(2.5, rel=0.02)  # the faces drawn evenly: the mean of 3.5 and 1.5


def test_an_ambient_term_without_faces_or_weight_is_off():
    assert not AmbientBoundary(BOX, [], weight=1.0).active
    assert not AmbientBoundary(BOX, ["x"], weight=0.0).active
    assert AmbientBoundary(BOX, ["x"], weight=0.1).active
    with pytest.raises(ValueError, match="ambient faces must be among"):
        AmbientBoundary(BOX, ["top"])


def test_total_variation_of_a_linear_field_is_its_change_over_one_voxel():
    """For sigma = a . p the change over one voxel h along each axis is a_k h: TV = w s sqrt(|a|^2 h^2 + eps^2)."""
    a = [0.3, -0.4, 1.2]
    w, s, eps = 0.7, 2.0, 1e-3
    term = TotalVariation(BOX, weight=w, points=128, scale=s, eps=eps)
    expected = w * s * math.sqrt(sum(x * x for x in a) * BOX.voxel_mm**2 + (eps * s) ** 2)
    assert value(term, Linear(a)) == pytest.approx(expected, rel=1e-5)


def test_total_variation_of_a_constant_is_its_smoothing_floor_and_its_gradient_points_downhill():
    term = TotalVariation(BOX, weight=1.0, points=256, scale=1.0, eps=1e-3)
    assert value(term, Linear([0.0, 0.0, 0.0], c=5.0)) == pytest.approx(1e-3, rel=1e-5)
    field = Linear([0.2, 0.0, -0.1])
    term(field, torch.Generator().manual_seed(3)).backward()
    g = field.a.grad
    # d/da of sqrt(|a|^2 h^2 + e^2) = a h^2 / sqrt(...): along a, so that a step down the gradient flattens the field
    assert torch.allclose(g / g.norm(), field.a.detach() / field.a.detach().norm(), atol=1e-5)


def test_total_variation_scales_with_the_deflections_as_the_misfit_does():
    """sigma scaled by c: the term by c (its weight a dimensionless number once s, the RMS deflection, scales by c
    too: c^2, as the squared misfit)."""
    a = [0.5, 0.1, 0.0]
    for c in (1.0, 10.0):
        term = TotalVariation(BOX, weight=0.1, points=64, scale=c, eps=0.0)
        got = value(term, Linear([c * x for x in a]))
        assert got == pytest.approx(0.1 * c * c * math.hypot(*a) * BOX.voxel_mm, rel=1e-5)


def test_a_negative_weight_is_one_sentence_and_zero_is_off():
    with pytest.raises(ValueError, match="cannot be negative"):
        TotalVariation(BOX, weight=-0.1, points=8, scale=1.0)
    assert not TotalVariation(BOX, weight=0.0, points=8, scale=1.0).active
    assert not TotalVariation(BOX, weight=0.1, points=8, scale=0.0).active
