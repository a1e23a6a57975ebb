import os

# Triton kernels (nerif.encoders.hash_kernel) run in Triton's interpreter on the CPU; the switch is read when a
# kernel is defined, so it is set before any test imports nerif.
os.environ.setdefault("TRITON_INTERPRET", "1")

import pytest
import torch


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)
