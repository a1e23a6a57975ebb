import torch

from nerif.data.phantoms import gaussian_blob
from nerif.geometry import arc_rig, sample_volume
from nerif.geometry import rays_in_box
from nerif.renderers import SAMPLERS, render_deflections
from nerif.renderers.occupancy import pack_bits, unpack_bits


def test_bitfield_round_trips():
    occ = torch.rand(4096) > 0.7
    bits = pack_bits(occ)
    assert bits.dtype == torch.uint8 and len(bits) == 512
    assert torch.equal(unpack_bits(bits), occ)


class _VolumeField(torch.nn.Module):
    """A fixed field (trilinear volume), shaped like a NeuralField for the sampler."""

    def __init__(self, sigma, box):
        super().__init__()
        self.box, self.sigma = box, torch.as_tensor(sigma, dtype=torch.float32)
        self.dummy = torch.nn.Parameter(torch.zeros(1))

    def forward(self, p):
        return sample_volume(self.sigma, self.box, p)


def _blob():
    ph = gaussian_blob(shape=(24, 24, 24), voxel_mm=2.0, width_mm=4.0)
    return ph, _VolumeField(ph.delta / abs(ph.delta.min()), ph.box)


def test_all_occupied_occupancy_equals_uniform():
    ph, field = _blob()
    o, d, _, vs = rays_in_box(ph.box, arc_rig(n_cameras=2, binning=40))
    o = o[torch.repeat_interleave(torch.arange(2), vs.diff())]
    occ = SAMPLERS.build({"name": "occupancy", "samples_per_ray": 24, "resolution": 32})
    uni = SAMPLERS.build({"name": "uniform", "samples_per_ray": 24})
    a = render_deflections(field, occ(ph.box, o, d, torch.Generator().manual_seed(5)), {"discrete": False}, 0.2)
    b = render_deflections(field, uni(ph.box, o, d, torch.Generator().manual_seed(5)), {"discrete": False}, 0.2)
    torch.testing.assert_close(a["discrete"], b["discrete"])


def test_grid_marks_the_blob_and_frees_far_cells_then_skips_samples():
    ph, field = _blob()
    occ = SAMPLERS.build({"name": "occupancy", "samples_per_ray": 48, "resolution": 16, "warmup": 0,
                          "update_every": 1, "full_updates": 3, "threshold": 1e-3})
    g = torch.Generator().manual_seed(0)
    for it in range(3):
        occ.update(ph.box, lambda p: field(p).abs(), it, g)
    centre = torch.zeros(1, 3)
    corner = torch.as_tensor(ph.box.half_mm * 0.95, dtype=torch.float32)[None]
    assert bool(occ.occupied(ph.box, centre)) and not bool(occ.occupied(ph.box, corner))
    cells = torch.as_tensor(ph.box.centres().reshape(-1, 3), dtype=torch.float32)
    assert 0 < float(occ.occupied(ph.box, cells).float().mean()) < 0.3  # the blob's cells, not the box
    o, d, _, vs = rays_in_box(ph.box, arc_rig(n_cameras=1, binning=40))
    s = occ(ph.box, o.expand(len(d), 3), d, g)
    assert len(s.positions) < 0.5 * 48 * len(d)
    # what was skipped carries no deflection: the result matches the uniform sampler's
    uni = SAMPLERS.build({"name": "uniform", "samples_per_ray": 48})(ph.box, o.expand(len(d), 3), d,
                                                                     torch.Generator().manual_seed(0))
    g2 = torch.Generator().manual_seed(0)
    s2 = occ(ph.box, o.expand(len(d), 3), d, g2)
    a = render_deflections(field, s2, {"discrete": False}, 0.2)["discrete"]
    b = render_deflections(field, uni, {"discrete": False}, 0.2)["discrete"]
    assert ((a - b).norm() / b.norm()).item() < 0.02


def test_the_grid_is_module_state_that_a_checkpoint_restores():
    """Buffers, not hand-kept attributes: a fresh grid loaded from another's state_dict marks the same cells, and
    the state of a checkpoint from before the buffers (``updates`` a plain int) still loads."""
    ph, field = _blob()
    occ = SAMPLERS.build({"name": "occupancy", "samples_per_ray": 16, "resolution": 16, "warmup": 0,
                          "update_every": 1, "threshold": 1e-3})
    assert set(dict(occ.named_buffers())) == {"density", "bits", "updates"}
    g = torch.Generator().manual_seed(0)
    for it in range(2):
        occ.update(ph.box, lambda p: field(p).abs(), it, g)
    state = occ.state_dict()
    p = torch.as_tensor(ph.box.centres().reshape(-1, 3), dtype=torch.float32)
    for st in (state, {**state, "updates": int(state["updates"])}):
        fresh = SAMPLERS.build({"name": "occupancy", "samples_per_ray": 16, "resolution": 16})
        assert bool(fresh.occupied(ph.box, p).all())  # new: every cell occupied
        fresh.load_state_dict(st)
        assert torch.equal(fresh.occupied(ph.box, p), occ.occupied(ph.box, p)) and int(fresh.updates) == 2
    assert 0.0 < float(occ.occupied(ph.box, p).float().mean()) < 1.0
