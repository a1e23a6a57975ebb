"""Datasets: phantoms, and scenes of rays with observed deflections."""
from nerif.data.phantoms import PHANTOMS, Phantom
from nerif.data.scene import DATASETS, Scene
from nerif.data import capture, transforms  # noqa: F401,E402  (registration)

__all__ = ["PHANTOMS", "Phantom", "DATASETS", "Scene"]
