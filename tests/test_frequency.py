"""The frequency (NeRF positional) encoding."""
import math

import torch

from nerif.encoders.frequency import Frequency


def test_frequency_encoding_layout():
    enc = Frequency()
    assert enc.out_dim == 39
    x = torch.tensor([[0.25, -0.5, 0.125]])
    f = enc(x)
    torch.testing.assert_close(f[0, :3], x[0])
    torch.testing.assert_close(f[0, 3:6], torch.sin(math.pi * x[0]))  # octave 0
    torch.testing.assert_close(f[0, 21:24], torch.cos(math.pi * x[0]))
