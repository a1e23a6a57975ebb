"""Masks: 2-D ray-sampling masks per view and the 3-D gate of the field.

Only ``none`` exists so far; the field already takes a ``gate`` callable (see :class:`nerif.field.NeuralField`).
A mask builder takes the scene and returns the gate, (N, 3) [mm] -> (N,) in [0, 1], or None.
"""
from nerif.registry import Registry

MASKS = Registry("mask")


@MASKS.register("none")
def no_mask(scene):
    """No 3-D gate."""
    return None
