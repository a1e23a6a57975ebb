"""Datasets (``DATASETS``: synthetic, capture, transforms) as scenes of rays with observed deflections, and the
phantoms (``PHANTOMS``) synthetic scenes are made of."""
from nerif.data.phantoms import PHANTOMS, Phantom
from nerif.data.scene import DATASETS, Scene

__all__ = ["PHANTOMS", "Phantom", "DATASETS", "Scene"]
