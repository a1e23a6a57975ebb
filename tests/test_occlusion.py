"""Occluders and saturated pixels (:mod:`nerif.sensing.occlusion`, :mod:`nerif.sensing.saturation`)."""
import numpy as np
import torch

from nerif.sensing.imaging import diffraction_blur
from nerif.sensing.occlusion import occluded
from nerif.sensing.patterns import PATTERNS
from nerif.sensing.saturation import saturated


def background(H=200, W=160):
    return diffraction_blur(torch.as_tensor(PATTERNS.build({"name": "poisson_disk"}, height=H, width=W, seed=1)),
                            2.1).numpy()


def test_a_dark_tube_without_texture_is_occluded_and_a_dimmer_textured_background_is_not():
    ref = background()
    ref[:, :80] *= 0.4  # illumination falling off across the view: still texture
    ref[150:, 60:100] = 0.08  # a dark burner tube, no texture
    hidden = occluded(ref)
    assert hidden[160:, 70:90].all()  # the tube
    assert hidden.mean() < (50 * 40 + 2 * 4 * 50 + 8 * 40 + 300) / ref.size  # the tube and its margin, no more
    assert not hidden[:140].any()  # the dim half is still background


def test_saturated_areas_in_either_exposure_are_found_with_a_margin_and_clipped_dots_are_not():
    ref, dist = background(), background()
    dist[50:60, 40:50] = 1.0  # the flame's light clipping the sensor
    ref[120:130, 100:110] = 1.0  # a reflection in the reference
    ref[100, 100] = dist[30, 30] = dist[31, 30] = 1.0  # the clipped centres of the pattern's dots
    s = saturated(dist, ref)
    assert s[50:60, 40:50].all() and s[49, 45] and s[120:130, 100:110].all()
    assert not s[100, 100] and not s[30, 30] and not s[80, 80]
    assert s.sum() == 2 * (12 * 12 - 4)  # each square grown by 1 px (a disc: no corners)
