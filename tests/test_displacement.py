import pytest
import torch

from nerif.geometry import arc_rig
from nerif.sensing.displacement import deflection_to_displacement, displacement_to_deflection


def test_central_ray_displacement_matches_the_hand_computation():
    cam = arc_rig(binning=1)[0]  # at +z, looking along -z: right = +x, down = -y
    d = torch.tensor([[0.0, 0.0, -1.0]], dtype=torch.float64)
    eps = torch.tensor([[1e-4, 2e-4, 0.0]], dtype=torch.float64)
    u = deflection_to_displacement(eps, d, cam)
    # u = eps * Z_D * M / pitch, Z_D = 800 mm, M = 112.37458 / 1600, pitch 0.02 mm
    k = 800 * (1 / (1 / 105 - 1 / 1600)) / 1600 / 0.02
    torch.testing.assert_close(u, torch.tensor([[1e-4 * k, -2e-4 * k]], dtype=torch.float64))


@pytest.mark.parametrize("view", [0, 5, 11])
def test_deflection_displacement_round_trip_is_exact(view):
    cam = arc_rig(binning=8)[view]
    d = cam.pixel_directions()[::37]
    eps = torch.randn(len(d), 3, dtype=torch.float64, generator=torch.Generator().manual_seed(view)) * 1e-4
    eps = eps - (eps * d).sum(-1, keepdim=True) * d  # straight ray through a bounded field: eps . d = 0
    back = displacement_to_deflection(deflection_to_displacement(eps, d, cam), d, cam)
    torch.testing.assert_close(back, eps, atol=1e-17, rtol=1e-12)


def test_view_displacements_are_in_sensor_pixels_whatever_the_binning():
    from nerif.sensing.displacement import view_displacements

    full, binned = arc_rig(n_cameras=2, binning=1), arc_rig(n_cameras=2, binning=8)
    d = torch.stack([full[0].pixel_directions()[1000], full[1].pixel_directions()[5000]])
    eps = torch.tensor([[1e-4, 2e-4, 0.0], [0.0, -1e-4, 3e-5]], dtype=torch.float64)
    views = torch.tensor([0, 1])
    u_full = view_displacements(eps, d, views, full)
    assert torch.allclose(view_displacements(eps, d, views, binned), u_full)
    assert torch.allclose(u_full[0], deflection_to_displacement(eps[:1], d[:1], full[0])[0])
