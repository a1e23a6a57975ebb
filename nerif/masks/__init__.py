"""Masks (``MASKS``: none, 2d, 3d): 2-D ray-sampling masks per view and the 3-D gate of the field."""
from nerif.masks.base import MASKS, Masks

__all__ = ["MASKS", "Masks"]
