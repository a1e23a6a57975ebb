"""Realistic BOS sensing: background patterns, finite-aperture optics, image warping and noise, optical flow."""
from nerif.sensing.flow import FLOW
from nerif.sensing.patterns import PATTERNS

__all__ = ["FLOW", "PATTERNS"]
