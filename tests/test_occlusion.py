"""Occluders and saturated pixels (:mod:`nerif.sensing.occlusion`, :mod:`nerif.sensing.saturation`)."""
import numpy as np
import pytest
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
    dist[50:74, 40:64] = 1.0  # the flame's light clipping the sensor over a dozen of the texture's widths
    ref[120:144, 100:124] = 1.0  # a reflection in the reference
    ref[100, 100] = dist[30, 30] = dist[31, 30] = 1.0  # the clipped centres of the pattern's dots
    s = saturated(dist, ref)
    assert s[50:74, 40:64].all() and s[49, 52] and s[120:144, 100:124].all()
    assert not s[100, 100] and not s[30, 30] and not s[80, 80]
    assert s.sum() == 2 * (26 * 26 - 4)  # each square grown by 1 px (a disc: no corners)


def test_a_bright_background_clipped_between_dark_dots_keeps_its_texture():
    """Issue 49: the shared real pair's background clips over wide areas between its dark dots, which carry the
    texture: none of it is saturated in the sense that matters (no readable background), while a textureless clipped
    area beside it is."""
    rng = np.random.default_rng(3)
    ref = np.ones((200, 160), np.float32)  # white, clipped
    for r, c in rng.integers(0, [200, 160], (2500, 2)):  # dark dots of 2-3 px, as dense as the real pair's
        ref[r:r + 2 + (r % 2), c:c + 2 + (c % 2)] = 0.2
    dist = ref.copy()
    dist[20:60, 20:60] = 1.0  # a flat clipped area: the texture is gone there
    s = saturated(dist, ref)
    assert s[25:55, 25:55].all()
    assert s[100:, :].mean() < 0.001


def test_a_sparse_patch_of_a_random_pattern_is_not_an_occluder():
    """Issue 49: a real random pattern has patches where its dots happen to be sparse; a window of the texture's
    width sees little texture there, and the old rule grew each such spot into a round blob 3 widths across. An
    occluder holds a disc of the texture's width without texture; a sparse patch does not."""
    rng = np.random.default_rng(5)
    ref = np.full((240, 200), 0.9, np.float32)
    for r, c in rng.integers(0, [240, 200], (3000, 2)):
        if not (60 <= r < 67 and 60 <= c < 67):  # a patch of 7 px with no dot
            ref[r:r + 2, c:c + 2] = 0.1
    ref[170:, 120:180] = 0.05  # a dark mount, 60 px wide
    hidden = occluded(ref)
    assert not hidden[:160].any()  # no blob anywhere in the pattern
    assert hidden[180:, 130:170].all()


@pytest.mark.parametrize("density, radius", [(0.02, 1.0), (0.04, 1.0), (0.1, 2.5)])
def test_a_uniformly_random_pattern_has_no_occluder_whatever_its_gaps_and_a_mount_in_it_is_found(density, radius):
    """Issue 56: the gaps of a random pattern of sparse dots (0.02 a px: 7 px apart, gaps 10 px wide, while the
    texture's width is 2.2 px) are many and alike; the rule of one texture width took 1.6-22 % of such patterns as
    occluded. The pattern's own gaps set the bar: none taken, a dark mount 60 px wide found whole."""
    img = PATTERNS.build({"name": "random_dots", "density": density, "radius_px": radius}, height=400, width=400,
                         seed=1)
    img = diffraction_blur(torch.as_tensor(img), 2.0).numpy()
    assert not occluded(img).any()
    img[300:, 150:210] = 0.0
    hidden = occluded(img)
    assert hidden[305:, 155:205].all() and not hidden[:250].any()
