"""Frequency (NeRF positional) encoding: the coordinates and their sines and cosines at octave frequencies.
(N, 3) in [-1, 1]^3 -> (N, 3 + 6 n_octaves)."""
import math

import torch
from torch import nn

from nerif.encoders.base import ENCODERS


@ENCODERS.register("frequency")
class Frequency(nn.Module):
    """NeRF positional encoding: ``[x, sin(2^k pi x), cos(2^k pi x)]`` for k < n_octaves.

    (N, 3) -> (N, 3 + 6 n_octaves); 39 features with the paper's 6 octaves.
    """

    def __init__(self, n_octaves: int = 6, include_input: bool = True):
        super().__init__()
        if n_octaves < 1:
            raise ValueError(f"frequency encoding needs at least one octave, got {n_octaves}")
        self.include_input = include_input
        self.register_buffer("freqs", (2.0 ** torch.arange(n_octaves)) * math.pi, persistent=False)
        self.out_dim = 3 * (2 * n_octaves + int(include_input))
        self.cells_across = 2**n_octaves  # half-periods of the finest octave across the network's [-1, 1]

    @staticmethod
    def features(encoder) -> int:
        """Features a point (``encoder``: this group's config)."""
        return 3 * (2 * int(encoder["n_octaves"]) + int(bool(encoder["include_input"])))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        xf = (x[..., None, :] * self.freqs[:, None]).flatten(-2)  # (N, 3 n_octaves)
        parts = [x] if self.include_input else []
        return torch.cat(parts + [torch.sin(xf), torch.cos(xf)], -1)
