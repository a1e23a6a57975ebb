"""No encoding (``encoder=none``): the MLP sees the normalised coordinates themselves. (N, 3) -> (N, 3)."""
import torch
from torch import nn

from nerif.encoders.base import ENCODERS


@ENCODERS.register("none")
class Identity(nn.Module):
    """No encoding: the MLP sees the coordinates themselves. (N, 3) -> (N, 3)."""

    out_dim = 3
    cells_across = 1  # the MLP alone: no structure finer than the box is encoded

    @staticmethod
    def features(encoder) -> int:
        """Features a point (``encoder``: this group's config)."""
        return 3

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x
