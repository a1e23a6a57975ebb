"""The encoder registry: every encoder built by name from a config."""

import pytest
import torch

from nerif.encoders import ENCODERS


@pytest.mark.parametrize("name", ["none", "frequency", "hash"])
def test_encoders_build_by_name(name):
    enc = ENCODERS.build({"name": name, **({"log2_table_size": 12, "max_resolution": 32} if name == "hash" else {})})
    assert enc(torch.zeros(7, 3)).shape == (7, enc.out_dim)
