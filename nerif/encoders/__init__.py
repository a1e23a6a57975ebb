"""Positional encoders: map network coordinates in [-1, 1]^3 to features (``ENCODERS``: none, frequency, hash)."""
from nerif.encoders.base import ENCODERS

__all__ = ["ENCODERS"]
