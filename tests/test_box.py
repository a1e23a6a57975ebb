"""The probe box: axes, normalisation, interpolation of volumes, ray intersection."""
import numpy as np
import pytest
import torch

from nerif.geometry import ProbeBox, sample_volume


def test_box_axes_and_normalisation():
    box = ProbeBox((4, 6, 4), 0.5)
    np.testing.assert_allclose(box.axes()[1], [-1.25, -0.75, -0.25, 0.25, 0.75, 1.25])
    p = torch.tensor([[1.0, 1.5, -1.0]])
    np.testing.assert_allclose(box.normalize(p).numpy(), [[2 / 3, 1.0, -2 / 3]])
    np.testing.assert_allclose(box.to_grid(p).numpy(), [[1.0, 1.0, -1.0]])
    q = torch.rand(20, 3) * 4 - 2
    torch.testing.assert_close(box.from_grid(box.to_grid(q)), q)


def test_sample_volume_reproduces_a_linear_field_and_voxel_values():
    box = ProbeBox((5, 7, 6), 1.0)
    c = box.centres()
    vol = torch.as_tensor(2 * c[..., 0] - c[..., 1] + 0.5 * c[..., 2], dtype=torch.float64)
    p = torch.rand(100, 3, dtype=torch.float64) * torch.tensor([4.0, 6.0, 5.0]) - torch.tensor([2.0, 3.0, 2.5])
    expect = 2 * p[:, 0] - p[:, 1] + 0.5 * p[:, 2]
    torch.testing.assert_close(sample_volume(vol, box, p), expect)
    torch.testing.assert_close(sample_volume(vol, box, torch.as_tensor(c[1, 2, 3])[None]), vol[1, 2, 3][None])


def test_ray_box_intersection_chords():
    box = ProbeBox((10, 20, 10), 1.0)  # 10 x 20 x 10 mm
    o = torch.tensor([[0.0, 0.0, 100.0], [0.0, 0.0, 100.0], [50.0, 0.0, 100.0]])
    d = torch.nn.functional.normalize(torch.tensor([[0.0, 0.0, -1.0], [0.0, 1.0, -20.0], [0.0, 0.0, -1.0]]), dim=-1)
    t0, t1, hit = box.intersect(o, d)
    assert hit.tolist() == [True, True, False]
    assert (t1 - t0)[0].item() == pytest.approx(10.0)
    assert t0[0].item() == pytest.approx(95.0)
