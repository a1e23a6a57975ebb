"""Saturated pixels (nerif.sensing.saturation): a clipped area without texture is lost, with a margin; clipped dot
centres and a bright background clipped between dark dots keep their texture and are not counted."""
import cv2
import numpy as np

from nerif.sensing.saturation import TOP, saturated

H = W = 160


def dots(seed=0, density=0.02, radius=2, clipped=True) -> np.ndarray:
    """Random discs on grey, in [0, 1]: bright ones whose centres clip (``clipped``), or dark ones."""
    rng = np.random.default_rng(seed)
    img = np.full((H, W), 0.5, np.float32)
    for r, c in rng.integers(0, [H, W], size=(int(density * H * W / (np.pi * radius**2)), 2)):
        cv2.circle(img, (int(c), int(r)), radius, TOP if clipped else 0.1, -1)
    return img


def grid_on_white(pitch=6) -> np.ndarray:
    """Dark dots of 3 px every ``pitch`` px on a background clipped at full scale between them."""
    img = np.full((H, W), TOP, np.float32)
    for r in range(2, H, pitch):
        for c in range(2, W, pitch):
            cv2.circle(img, (c, r), 1, 0.1, -1)
    return img


def test_a_clean_pair_and_clipped_dot_centres_lose_nothing():
    ref = dots(0)
    assert (ref == TOP).any()  # the dots' centres reach the top code value
    assert not saturated(ref, ref, width_px=4.0).any()
    white = grid_on_white()
    assert (white == TOP).mean() > 0.5
    assert not saturated(white, white, width_px=4.0).any()


def test_a_clipped_patch_without_texture_is_lost_with_its_margin():
    ref = dots(2, density=0.1, clipped=False)
    dist = ref.copy()
    dist[40:90, 50:110] = TOP  # a reflection or the flame's light clipping a 50 x 60 px patch
    lost = saturated(dist, ref, margin_px=2, width_px=4.0)
    assert lost[40:90, 50:110].all()
    assert lost[38:92, 48:112].sum() == lost.sum()  # nothing beyond the margin
    assert lost[38, 60] and not lost[36, 60]
    # the same patch in the reference is lost alike
    assert np.array_equal(saturated(ref, dist, margin_px=2, width_px=4.0), lost)


def test_a_clipped_area_narrower_than_the_texture_is_kept():
    ref = dots(3, density=0.1, clipped=False)
    dist = ref.copy()
    dist[60:63, 20:140] = TOP  # a 3 px streak: texture on both sides within two widths
    assert not saturated(dist, ref, width_px=4.0).any()
