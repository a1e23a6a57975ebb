"""A background's texture statistics: its correlation length, the detectors' width, the flow's shrink factor."""
import cv2
import numpy as np
import pytest

from nerif.sensing.texture import AUTO_WIDTH_RANGE_PX, shrink_factor, texture_scale_px, texture_width


@pytest.mark.parametrize("blur_px", [1.0, 1.5, 2.5])
def test_the_correlation_length_of_blurred_white_noise_is_what_its_autocorrelation_says(blur_px):
    """White noise blurred by a Gaussian of sigma ``s`` has the autocorrelation ``exp(-r^2 / (2 L^2))``,
    ``L = sqrt(2) s``. :func:`texture_scale_px` reads ``sqrt(2) std / rms |grad|`` with central differences over
    2 px, whose variance is ``(1 - exp(-2 / L^2)) / 2`` a component: it reads ``sqrt(2 / (1 - exp(-2 / L^2)))``,
    which tends to ``L`` for a coarse texture (within 5 %: the 8 px high-pass)."""
    noise = np.random.default_rng(0).standard_normal((400, 400)).astype(np.float32)
    texture = cv2.GaussianBlur(noise, (0, 0), blur_px)
    L = np.sqrt(2) * blur_px
    assert texture_scale_px(texture) == pytest.approx(np.sqrt(2 / (1 - np.exp(-2 / L**2))), rel=0.05)
    assert texture_width(texture) == pytest.approx(np.clip(1.5 * texture_scale_px(texture), *AUTO_WIDTH_RANGE_PX))


def test_a_texture_k_times_coarser_is_measured_on_images_about_k_over_two_times_smaller():
    assert shrink_factor(1.45, "auto") == 1 and shrink_factor(3.2, "auto") == 2 and shrink_factor(7.3, "auto") == 5
    assert shrink_factor(9.0, 3) == 3
    with pytest.raises(ValueError, match="measure.flow_factor=0"):
        shrink_factor(1.0, 0)
