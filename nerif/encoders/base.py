"""The encoder registry: every module of :mod:`nerif.encoders` registers its encoders here.

An encoder is an ``nn.Module`` with ``out_dim`` and ``forward(x: (N, 3)) -> (N, out_dim)``, mapping network
coordinates in [-1, 1]^3 to features.
"""
from nerif.registry import Registry

ENCODERS = Registry("encoder", package="nerif.encoders")
