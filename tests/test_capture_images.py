"""A capture's image files (:mod:`nerif.data.capture_images`): their headers checked before any decoding, each
image decoded once to [0, 1] of its full scale, several exposures of a state averaged with their noise."""
import cv2
import numpy as np
import pytest

from nerif.data.capture_images import check_images, exposure_noise, lossy_images, read_exposures, read_images

SENSOR = (64, 48)  # (width, height) px


def write(path, image):
    assert cv2.imwrite(str(path), image)
    return path


def test_greyscale_images_of_the_sensor_read_to_their_full_scale(tmp_path):
    a8 = np.zeros((48, 64), np.uint8)
    a8[0, 0], a8[1, 1] = 255, 51
    a16 = np.zeros((48, 64), np.uint16)
    a16[0, 0], a16[1, 1] = 65535, 13107
    paths = [write(tmp_path / "a.png", a8), write(tmp_path / "b.tif", a16)]
    check_images(paths[:1], SENSOR)
    check_images(paths[1:], SENSOR)
    eight, sixteen = read_images(paths[:1], SENSOR)[0], read_images(paths[1:], SENSOR)[0]
    assert eight.dtype == np.float32 and eight.shape == (48, 64)
    assert (eight[0, 0], eight[1, 1]) == (1.0, pytest.approx(0.2)) and (sixteen[0, 0], sixteen[1, 1]) == (
        1.0, pytest.approx(0.2))


@pytest.mark.parametrize("image, message", [
    (np.zeros((48, 64, 3), np.uint8), "is a colour image (3 channels); BOS needs greyscale"),
    (np.zeros((64, 48), np.uint8), "is 48 x 64 px but the rig's sensor_px (a calibration's image_size) is 64 x 48: "
                                   "sensor_px is (width, height), swap its two numbers"),
    (np.zeros((24, 32), np.uint8), "binned 2 x 2 in the camera? Then give the images' size as sensor_px and the "
                                   "binned pixel's pitch (2 times the sensor's) as pitch_um"),
    (np.zeros((40, 64), np.uint8), "every image must be a full frame of the same camera"),
])
def test_an_image_that_does_not_fit_the_capture_is_one_sentence_from_its_header_and_when_decoded(tmp_path, image,
                                                                                               message):
    path = write(tmp_path / "bad.png", image)
    for check in (check_images, read_images):
        with pytest.raises(ValueError) as e:
            check([path], SENSOR)
        assert message in str(e.value) and str(path) in str(e.value)


def test_one_bit_depth_for_every_image_and_a_file_that_is_no_image_named(tmp_path):
    paths = [write(tmp_path / "a.png", np.zeros((48, 64), np.uint8)),
             write(tmp_path / "b.png", np.zeros((48, 64), np.uint16))]
    with pytest.raises(ValueError, match="b.png is uint16 but a.png is uint8: save every image with the same bit"):
        check_images(paths, SENSOR)
    (tmp_path / "c.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="c.png is not a readable image"):
        check_images([tmp_path / "c.png"], SENSOR)


def test_the_noise_of_a_mean_of_exposures_is_their_spread_over_the_root_of_their_number():
    """K exposures of one state with independent noise of 0.01: the mean's noise 0.01 / sqrt(K), within the
    estimate's own scatter (about 1 / sqrt(2 (K - 1) pixels) of it: 0.3 % here); one exposure tells nothing."""
    rng = np.random.default_rng(0)
    scene = rng.uniform(0.2, 0.8, (200, 300))
    for k in (2, 4):
        stack = scene + 0.01 * rng.standard_normal((k, 200, 300))
        assert exposure_noise(stack) == pytest.approx(0.01 / np.sqrt(k), rel=0.02)
    assert exposure_noise(scene[None]) is None


def test_exposures_are_averaged_and_a_pixel_clipped_in_one_stays_clipped(tmp_path):
    a = np.full((48, 64), 100, np.uint8)
    b = np.full((48, 64), 110, np.uint8)
    a[5, 5], b[5, 5] = 255, 200  # clipped in one exposure: what it recorded there is lost
    files = (write(tmp_path / "a.png", a), write(tmp_path / "b.png", b))
    (mean,), (noise,) = read_exposures([files], SENSOR)
    assert mean[0, 0] == pytest.approx(105 / 255) and mean[5, 5] == 1.0
    # two exposures x, y: a pixel's unbiased variance (x - y)^2 / 2; 10 counts apart but at one pixel 55
    variance = ((10 / 255) ** 2 * (48 * 64 - 1) + (55 / 255) ** 2) / 2 / (48 * 64)
    assert noise == pytest.approx(np.sqrt(variance / 2), rel=1e-5)
    (single,), (none,) = read_exposures([files[:1]], SENSOR)
    assert none is None and single[0, 0] == pytest.approx(100 / 255)


def test_jpeg_images_are_said_to_be_lossy_once():
    from pathlib import Path

    said = lossy_images([Path("a.png"), Path("b.JPG"), Path("c.jpeg")])
    assert said.startswith("2 of the capture's 3 images are JPEG (b.JPG, ...), a lossy format")
    assert lossy_images([Path("a.png"), Path("b.tif")]) == ""
