"""Samplers: packed samples along rays."""
import torch

from nerif.geometry import ProbeBox
from nerif.renderers import SAMPLERS, integrate


BOX = ProbeBox((10, 20, 10), 1.0)


def _rays():
    o = torch.tensor([[0.0, 0.0, 100.0], [3.0, -4.0, 100.0], [80.0, 0.0, 100.0]])
    d = torch.nn.functional.normalize(torch.tensor([[0.0, 0.0, -1.0], [0.01, 0.02, -1.0], [0.0, 0.0, -1.0]]), dim=-1)
    return o, d


def test_uniform_sampler_packs_k_samples_per_hit_ray_and_none_for_misses():
    o, d = _rays()
    s = SAMPLERS.build({"name": "uniform", "samples_per_ray": 8})(BOX, o, d, torch.Generator().manual_seed(0))
    assert s.per_ray.tolist() == [8, 8, 0]
    assert bool(BOX.contains(s.positions).all())
    t0, t1, _ = BOX.intersect(o, d)
    torch.testing.assert_close(integrate(torch.ones(len(s.dt), 1), s)[:, 0], torch.stack([t1[0] - t0[0], t1[1] - t0[1],
                                                                                        torch.tensor(0.0)]))


def test_jitter_is_one_offset_per_ray_within_a_step():
    o, d = _rays()
    s = SAMPLERS.build({"name": "uniform", "samples_per_ray": 8})(BOX, o[:1], d[:1], torch.Generator().manual_seed(3))
    z = s.positions[:, 2]
    gaps = z[:-1] - z[1:]
    torch.testing.assert_close(gaps, torch.full_like(gaps, 10.0 / 8))  # equal spacing: one shared offset
    assert 5.0 - 10.0 / 8 <= z[0].item() <= 5.0  # first sample inside the first step
