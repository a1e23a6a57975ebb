"""The encoder registry: every module of :mod:`nerif.encoders` registers its encoders here.

An encoder is an ``nn.Module`` with ``out_dim``, ``cells_across`` (the finest structure it encodes: cells across the
network's [-1, 1], which sets the field's finest cell, :attr:`nerif.field.NeuralField.finest_cell_mm`) and
``forward(x: (N, 3)) -> (N, out_dim)``, mapping network coordinates in [-1, 1]^3 to features.
"""
from nerif.registry import Registry

ENCODERS = Registry("encoder", package="nerif.encoders")
