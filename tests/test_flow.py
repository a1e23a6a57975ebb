
import numpy as np
import pytest
import torch

from nerif.sensing.flow import FLOW
from nerif.sensing.imaging import diffraction_blur, warp
from nerif.sensing.patterns import PATTERNS


@pytest.mark.parametrize("flow,pattern", [("farneback", "poisson_disk"), ("farneback", "wavelet_noise"),
                                          ("dis", "poisson_disk")])
def test_optical_flow_recovers_a_known_smooth_displacement(flow, pattern):
    H, W = 240, 320
    background = torch.as_tensor(PATTERNS.build({"name": pattern}, height=H, width=W, seed=1))
    r, c = torch.meshgrid(torch.arange(H, dtype=torch.float32), torch.arange(W, dtype=torch.float32), indexing="ij")
    u = torch.stack([0.8 * torch.sin(2 * np.pi * r / 160) * torch.cos(2 * np.pi * c / 200),
                     0.6 * torch.cos(2 * np.pi * c / 150)], -1)
    reference, distorted = diffraction_blur(background, 2.1), diffraction_blur(warp(background, u), 2.1)
    est = FLOW.build({"name": flow}, distorted=distorted.numpy(), reference=reference.numpy())
    err = (est - u.numpy())[20:-20, 20:-20]
    rms = float(np.sqrt((err**2).sum(-1).mean()))
    assert rms < 0.1, rms
    assert float(np.sqrt((u.numpy() ** 2).sum(-1).mean())) > 5 * rms  # the displacement itself is well above it


def test_unknown_dis_preset_is_named():
    with pytest.raises(ValueError, match="DIS preset 'slow' unknown"):
        FLOW.build({"name": "dis", "preset": "slow"}, distorted=np.zeros((8, 8)), reference=np.zeros((8, 8)))
