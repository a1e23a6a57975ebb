"""Deflection rendering: integration along rays and the measurable (perpendicular) part."""
import torch

from nerif.geometry import ProbeBox
from nerif.renderers import SAMPLERS, render_deflections

BOX = ProbeBox((10, 20, 10), 1.0)


def _rays():
    """Two rays through the box (one tilted) and one that misses it."""
    o = torch.tensor([[0.0, 0.0, 100.0], [3.0, -4.0, 100.0], [80.0, 0.0, 100.0]])
    return o, torch.nn.functional.normalize(torch.tensor([[0.0, 0.0, -1.0], [0.01, 0.02, -1.0], [0.0, 0.0, -1.0]]), dim=-1)


def test_a_linear_field_deflects_by_gradient_times_chord_for_both_operators():
    o, d = _rays()
    s = SAMPLERS.build({"name": "uniform", "samples_per_ray": 16, "jitter": False})(BOX, o, d)
    g = torch.tensor([0.02, -0.01, 0.005])
    eps = render_deflections(lambda p: p @ g, s, {"auto": False, "discrete": False}, step_mm=0.1)
    t0, t1, hit = BOX.intersect(o, d)
    expect = ((t1 - t0).clamp_min(0) * hit)[:, None] * g
    for name in ("auto", "discrete"):
        torch.testing.assert_close(eps[name], expect, rtol=1e-5, atol=1e-7)


def test_perpendicular_part_is_what_a_camera_measures():
    from nerif.renderers import perpendicular

    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(50, 3, generator=g, dtype=torch.float64), dim=-1)
    eps = torch.randn(50, 3, generator=g, dtype=torch.float64)
    p = perpendicular(eps, d)
    torch.testing.assert_close((p * d).sum(-1), torch.zeros(50, dtype=torch.float64), atol=1e-15, rtol=0)
    torch.testing.assert_close(perpendicular(p, d), p)  # a projection
    torch.testing.assert_close(eps - p, (eps * d).sum(-1, keepdim=True) * d)


def test_the_renderer_evaluates_any_number_of_rays_in_passes_as_in_one_and_projects_what_is_measured():
    """A linear field's deflections, gradient times chord (closed form), for more rays than one pass holds, and only
    their part perpendicular to the rays where only that is measured; a step's operators and their cost."""
    from nerif.renderers import DeflectionRenderer, perpendicular

    g = torch.tensor([0.02, -0.01, 0.005], dtype=torch.float64)
    o, d = _rays()
    o, d = o.double().repeat(3000, 1), d.double().repeat(3000, 1)  # 9000 rays: 3 passes of 4096 at 16 samples
    t0, t1, hit = BOX.intersect(o, d)
    chord = ((t1 - t0).clamp_min(0) * hit)[:, None]
    full = DeflectionRenderer({"discrete": 1.0}, "axes", 0.1, False, 16).evaluate(lambda p: p @ g, BOX, o, d)
    for name in ("auto", "discrete"):
        torch.testing.assert_close(full[name], chord * g, rtol=1e-5, atol=1e-7)
    seen = DeflectionRenderer({"discrete": 1.0}, "axes", 0.1, True, 16).evaluate(lambda p: p @ g, BOX, o, d, ("discrete",))
    torch.testing.assert_close(seen["discrete"], perpendicular(chord * g, d), rtol=1e-5, atol=1e-7)
    both = DeflectionRenderer({"auto": 0.5, "discrete": 1.0}, "across", 0.1, True, 16)
    assert both.fitted_operator == "discrete" and both.evaluations_per_sample == 1 + 4
    assert DeflectionRenderer({"auto": 1.0, "discrete": 0.0}, "axes", 0.1, True, 16).fitted_operator == "auto"
