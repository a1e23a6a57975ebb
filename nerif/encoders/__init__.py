"""Positional encoders: map network coordinates in [-1, 1]^3 to features.

Each encoder is an ``nn.Module`` with ``out_dim`` and ``forward(x: (N, 3)) -> (N, out_dim)``.
"""
from nerif.registry import Registry

ENCODERS = Registry("encoder")

from nerif.encoders import frequency, hash, identity  # noqa: E402,F401  (registration)

__all__ = ["ENCODERS"]
