"""Sensing models: ideal vectors, and the part of them a camera measures."""
import torch

from nerif.data.phantoms import gaussian_blob
from nerif.geometry import arc_rig, rays_in_box
from nerif.sensing import SENSING


def _sense(name, ph, cams):
    o, d, pixel, vs = rays_in_box(ph.box, cams)
    delta = torch.as_tensor(ph.delta, dtype=torch.float64)
    eps, record = SENSING.build({"name": name}, delta=delta, box=ph.box, cameras=cams, dirs=d.double(), pixel=pixel,
                                view_start=vs, step_mm=None, rig_binning=cams[0].binning)
    return eps, d.double(), record


def test_perpendicular_sensing_keeps_what_a_camera_measures_of_the_ideal_vectors():
    # a blob off-centre, cut by the box: the along-ray component (sigma(exit) - sigma(entry)) is not zero
    ph = gaussian_blob(shape=(16, 16, 16), voxel_mm=2.0, width_mm=6.0, centre_mm=(0.0, 0.0, 12.0))
    cams = arc_rig(n_cameras=3, binning=40)
    ideal, d, rec = _sense("ideal", ph, cams)
    measured, _, rec_p = _sense("perpendicular", ph, cams)
    assert rec is None and rec_p is None
    along = (ideal * d).sum(-1)
    assert float(along.abs().max()) > 0.05 * float(ideal.norm(dim=-1).max())
    torch.testing.assert_close(measured, ideal - along[:, None] * d)
    assert float((measured * d).sum(-1).abs().max()) < 1e-6 * float(measured.norm(dim=-1).max())


def test_the_registry_names_the_three_models():
    assert SENSING.names() == ["ideal", "perpendicular", "realistic"]
