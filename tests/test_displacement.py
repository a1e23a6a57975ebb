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


def test_a_scenes_displacements_are_in_sensor_pixels_whatever_the_binning():
    """``Scene.to_displacement``: the full sensor's pixels for rays of binned cameras, as the full-sensor camera
    maps them, and back to the deflections by ``displacement_to_deflection``."""
    from nerif.data.scene import Scene, views_of
    from nerif.geometry import ProbeBox, rays_in_box
    from nerif.physics import Ambient

    box = ProbeBox((16, 16, 16), 2.0)
    binned = arc_rig(n_cameras=2, binning=8)
    origins, d, pixel, starts = rays_in_box(box, binned)
    g = torch.Generator().manual_seed(3)
    eps = torch.randn(len(d), 3, dtype=torch.float64, generator=g) * 1e-4
    eps = eps - (eps * d.double()).sum(-1, keepdim=True) * d.double()
    scene = Scene(box=box, ambient=Ambient(293.0, 1.000277, 2000.0), views=views_of(binned), origins=origins, dirs=d,
                  eps=eps.float(), pixel=pixel, view_start=starts)
    u = scene.to_displacement(eps)
    full = arc_rig(n_cameras=2, binning=1)
    for v in range(2):
        sl = scene.view_slice(v)
        torch.testing.assert_close(u[sl], deflection_to_displacement(eps[sl], d[sl].double(), full[v]))
        torch.testing.assert_close(displacement_to_deflection(u[sl], d[sl].double(), full[v]), eps[sl])
    assert float(u.abs().max()) > 1.0  # 1e-4 rad is pixels on this rig: the test compares something
