"""Datasets: phantoms, and scenes of rays with observed deflections."""
from nerif.data.phantoms import PHANTOMS, Phantom
from nerif.data.scene import DATASETS, Scene

__all__ = ["PHANTOMS", "Phantom", "DATASETS", "Scene"]
