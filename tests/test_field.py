"""The neural field: ambient start, prior interval, the 3-D gate."""
import pytest
import torch

from nerif.encoders import ENCODERS
from nerif.field import NeuralField
from nerif.geometry import ProbeBox

BOX = ProbeBox((20, 30, 20), 1.0)
SMALL_HASH = {"name": "hash", "log2_table_size": 12, "max_resolution": 64}


@pytest.mark.parametrize("enc", [{"name": "none"}, {"name": "frequency"}, SMALL_HASH])
def test_initial_field_is_ambient(enc):
    field = NeuralField(ENCODERS.build(enc), BOX)
    p = torch.rand(1000, 3) * 30 - 15
    assert field(p).abs().max() < 1e-6


def test_output_stays_in_the_prior_interval():
    field = NeuralField(ENCODERS.build({"name": "frequency"}), BOX, prior=(-1.2, 0.3))
    with torch.no_grad():
        for prm in field.parameters():
            prm.normal_(0, 5.0)
    s = field(torch.rand(2000, 3) * 30 - 15)
    assert s.min() >= -1.2 and s.max() <= 0.3 and s.max() - s.min() > 1.0


def test_prior_must_contain_ambient():
    with pytest.raises(ValueError, match="ambient"):
        NeuralField(ENCODERS.build({"name": "none"}), BOX, prior=(0.1, 1.0))


def test_gate_multiplies_the_field():
    gate = lambda p: (p[:, 0] > 0).float()  # noqa: E731
    field = NeuralField(ENCODERS.build({"name": "frequency"}), BOX, gate=gate)
    with torch.no_grad():
        field.mlp[-1].weight.normal_()
    p = torch.rand(500, 3) * 20 - 10
    s = field(p)
    assert s[p[:, 0] < 0].abs().max() == 0 and s[p[:, 0] > 0].abs().max() > 0


def test_the_network_is_not_evaluated_where_the_3d_mask_is_zero():
    from nerif.data import DATASETS
    from nerif.masks import MASKS

    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "T_max": 2000.0,
                            "phantom": {"name": "gaussian_blob", "shape": [20, 20, 20], "voxel_mm": 2.0, "width_mm": 4.0},
                            "rig": {"name": "arc", "n_cameras": 6, "binning": 20}})
    masks = MASKS.build({"name": "3d"}, scene=scene)
    field = NeuralField(ENCODERS.build({"name": "frequency"}), scene.box, gate=masks.gate)
    seen = []
    field.mlp.register_forward_hook(lambda m, i, o: seen.append(len(i[0])))
    p = torch.as_tensor(scene.box.centres().reshape(-1, 3), dtype=torch.float32)
    s = field(p)
    assert seen[0] < 0.6 * len(p) and s[torch.as_tensor(~masks.volume.reshape(-1))].abs().max() == 0


def test_the_fields_finest_cell_is_the_longest_edge_over_the_encoders_cells():
    """Issue 66: a hash of 64 cells across a 30 mm box has 0.47 mm cells, 6 octaves 30 / 64 mm, no encoding the box;
    an encoder that declares no ``cells_across`` (a user's new one) counts a voxel, and the run goes on."""
    assert NeuralField(ENCODERS.build(SMALL_HASH), BOX).finest_cell_mm == pytest.approx(30 / 64)
    assert NeuralField(ENCODERS.build({"name": "frequency"}), BOX).finest_cell_mm == pytest.approx(30 / 64)
    assert NeuralField(ENCODERS.build({"name": "none"}), BOX).finest_cell_mm == pytest.approx(30.0)

    class Plain(torch.nn.Module):
        out_dim = 3

        def forward(self, x):
            return x

    assert NeuralField(Plain(), BOX).finest_cell_mm == BOX.voxel_mm
