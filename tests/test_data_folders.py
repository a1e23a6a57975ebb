"""The checks shared by the readers of real data (:mod:`nerif.data.folders`)."""
import logging

import numpy as np
import pytest

from nerif.data.folders import (blocks_inside, dataset_folder, finite_or_masked, read_truth, region_of_interest,
                                resolve_binning)
from nerif.geometry import ProbeBox, arc_rig

SENSOR = "the 720 x 1280 px sensor"


def thin_lens_pixels_per_mm(focal_mm=105.0, distance_mm=800.0, behind_mm=800.0, pitch_um=20.0) -> float:
    """Sensor pixels a millimetre at the probe centre spans, a thin lens focused on the background: the image
    distance ``1 / (1/f - 1/(d + b))`` over the object distance ``d``, in pixels of ``pitch_um``."""
    image_mm = 1.0 / (1.0 / focal_mm - 1.0 / (distance_mm + behind_mm))
    return image_mm / distance_mm / (pitch_um * 1e-3)


@pytest.mark.parametrize("voxel_mm, expected", [(1.0, 8), (2.0, 16), (0.5, 4)])
def test_auto_binning_puts_about_one_ray_across_a_voxel(voxel_mm, expected, caplog):
    """720 x 1280 px sensors share the divisors 1, 2, 4, 5, 8, 10, 16, 20, 40, 80; a voxel spans 7.02 px per mm
    at the probe (thin lens): 7.0, 14.0 and 3.5 px take the divisor nearest in ratio: 8, 16 and 4."""
    cams = arc_rig(n_cameras=3, binning=1)
    per_voxel = thin_lens_pixels_per_mm() * voxel_mm
    divisors = [b for b in range(1, 81) if 80 % b == 0]
    assert min(divisors, key=lambda b: abs(np.log(b / per_voxel))) == expected  # the closed form's choice
    with caplog.at_level(logging.INFO, logger="nerif.data.folders"):
        assert resolve_binning("auto", cams, ProbeBox((10, 10, 10), voxel_mm), SENSOR) == expected
    assert f"{expected} x {expected} pixels a ray" in caplog.text and f"{per_voxel:.1f} pixels span" in caplog.text


def test_a_whole_number_binning_is_taken_and_a_coarse_one_warned(caplog):
    cams, box = arc_rig(n_cameras=2, binning=1), ProbeBox((10, 10, 10), 1.0)
    assert resolve_binning(4.0, cams, box, SENSOR) == 4  # 4.0 is 4
    with caplog.at_level(logging.WARNING, logger="nerif.data.folders"):
        assert resolve_binning(8, cams, box, SENSOR) == 8  # 1.1 voxels a ray: no warning
        assert not caplog.records
        assert resolve_binning(40, cams, box, SENSOR) == 40  # 5.7 voxels a ray: above COARSE = 2.5
    assert "a ray spans 5.7 voxels" in caplog.text and "(18 x 32 rays a view)" in caplog.text
    assert "auto: 8" in caplog.text


@pytest.mark.parametrize("setting, message", [
    (0, "data.binning=0: auto or a whole number of pixels (at least 1)"),
    (2.5, "data.binning=2.5: auto or a whole number"),
    (True, "data.binning=True: auto or a whole number"),
    ("four", "data.binning='four': auto or a whole number"),
    (7, f"data.binning=7 must divide {SENSOR}"),
])
def test_a_binning_that_cannot_be_is_one_sentence(setting, message):
    with pytest.raises(ValueError) as e:
        resolve_binning(setting, arc_rig(n_cameras=2, binning=1), None, SENSOR)
    assert message in str(e.value)


def test_a_region_of_interest_is_its_rectangle_and_nothing_outside_the_image():
    roi = region_of_interest(2, 1, 3, 2, width=6, height=4, what="roi of camera 00")
    expected = np.zeros((4, 6), bool)
    expected[1:3, 2:5] = True
    np.testing.assert_array_equal(roi, expected)
    assert region_of_interest(0, 0, 6, 4, 6, 4, "all").all()
    for x, y, w, h in [(4, 0, 3, 1), (0, 3, 1, 2), (-1, 0, 2, 2), (0, 0, 0, 2)]:
        with pytest.raises(ValueError, match="roi of camera 00 is not inside the 6 x 4 px image"):
            region_of_interest(x, y, w, h, 6, 4, "roi of camera 00")


def test_blocks_inside_a_region_are_those_wholly_inside_it():
    """An 8 x 8 px region with one pixel cut from its corner, on 2 x 2 blocks of a 16 x 16 sensor: the block
    holding the cut pixel is not inside, its neighbours are."""
    region = np.zeros((16, 16), bool)
    region[4:12, 4:12] = True
    region[4, 4] = False
    blocks = blocks_inside(region, 8, 8)
    expected = np.zeros((8, 8), bool)
    expected[2:6, 2:6] = True
    expected[2, 2] = False
    np.testing.assert_array_equal(blocks, expected)


def test_the_dataset_folder_is_an_existing_folder_or_one_sentence(tmp_path):
    assert dataset_folder(str(tmp_path)) == tmp_path
    for unset in (None, "", "???"):
        with pytest.raises(ValueError, match="data.root is not set: give the dataset folder"):
            dataset_folder(unset)
    with pytest.raises(FileNotFoundError, match="is not a folder"):
        dataset_folder(tmp_path / "missing")
    (tmp_path / "file").write_text("")
    with pytest.raises(FileNotFoundError, match="is not a folder"):
        dataset_folder(tmp_path / "file")


def test_displacements_that_are_not_finite_are_left_out_and_counted(caplog):
    u = np.zeros((3, 4, 2))
    u[0, 1, 0], u[2, 3, 1], u[1, 2] = np.nan, np.inf, -np.inf
    with caplog.at_level(logging.INFO, logger="nerif.data.folders"):
        ok = finite_or_masked(u, "camera 01")
    expected = np.ones((3, 4), bool)
    expected[0, 1] = expected[2, 3] = expected[1, 2] = False
    np.testing.assert_array_equal(ok, expected)
    assert "camera 01: 3 of 12 displacement estimates are left out" in caplog.text


def test_the_truth_is_read_on_the_probe_grid_or_named(tmp_path):
    box = ProbeBox((3, 4, 5), 1.0)
    T = np.full(box.shape, 300.0)
    T[1, 2, 3] = 1800.0
    np.save(tmp_path / "T.npy", T)
    np.savez(tmp_path / "volume.npz", T=T, sigma=np.zeros(box.shape))  # several arrays: the one named T
    np.testing.assert_array_equal(read_truth(tmp_path / "T.npy", box), T)
    np.testing.assert_array_equal(read_truth(tmp_path / "volume.npz", box), T)
    with pytest.raises(ValueError, match=r"has shape \(3, 4, 5\), the probe grid is \(5, 4, 3\)"):
        read_truth(tmp_path / "T.npy", ProbeBox((5, 4, 3), 1.0))
    np.save(tmp_path / "cold.npy", np.full(box.shape, -5.0))
    with pytest.raises(ValueError, match="cold.npy has a temperature of -5 K, below 1 K: not physical"):
        read_truth(tmp_path / "cold.npy", box)
