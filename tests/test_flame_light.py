"""The flame's own light on a distorted exposure (nerif.sensing.flame_light): a background-off exposure taken off
exactly, less its dark level; light with structure told from a smooth illumination drift."""
import cv2
import numpy as np
import pytest

from nerif.sensing.flame_light import LIGHT_SEEN, light_structure, without_flame_light

H = W = 192


def texture(seed=0, width_px=2.0) -> np.ndarray:
    """A random background texture in [0.2, 0.8] of full scale, ``width_px`` wide."""
    n = cv2.GaussianBlur(np.random.default_rng(seed).standard_normal((H, W)).astype(np.float32), (0, 0), width_px)
    return np.float32(0.5 + 0.3 * n / np.abs(n).max())


def blob(amplitude, radius_px, centre=(96, 96)) -> np.ndarray:
    rows, cols = np.mgrid[0:H, 0:W].astype(np.float32)
    r2 = (rows - centre[0]) ** 2 + (cols - centre[1]) ** 2
    return np.float32(amplitude * np.exp(-r2 / (2 * radius_px**2)))


def test_the_background_off_exposure_is_taken_off_less_its_dark_level():
    reference = texture()
    light = blob(0.3, 8.0)
    dark = 0.02
    out = without_flame_light(reference + light + dark, light + dark)
    # the flame's exposure less its median (the dark level: the light covers far less than half of the view)
    assert np.allclose(out, reference + dark, atol=1e-6)


@pytest.mark.parametrize("drift", [0.0, 0.05])
def test_a_smooth_illumination_drift_is_not_light(drift):
    reference = texture(1)
    ramp = 1 + drift + 0.1 * np.linspace(0, 1, W, dtype=np.float32)[None, :]  # a gain ramp of 10 % across
    assert light_structure(reference * ramp, reference, 2.0) < 0.5 * LIGHT_SEEN


def test_a_flames_glow_is_seen_in_proportion_to_its_brightness():
    reference = texture(2)
    weak = light_structure(reference + blob(0.05, 10.0), reference, 2.0)
    strong = light_structure(reference + blob(0.3, 10.0), reference, 2.0)
    assert strong > LIGHT_SEEN
    # the measure is the glow's share of the local brightness (0.5), less its own blur: linear in the glow
    assert strong / weak == pytest.approx(6.0, rel=0.15)
    assert strong < 0.3 / 0.5
