"""``python -m nerif.measure``: the measurement stage on one image pair without a rig, and what it keeps of a real
camera's images (issue 49)."""
import json

import cv2
import numpy as np
import pytest

from nerif.measure import main
from nerif.sensing.measurement import CAUSES
from tests.helpers import shared_data


@pytest.fixture(scope="module")
def real_pair(tmp_path_factory):
    """The shared real pair (a stratified tank seen through a bright random-dot background) measured with rays of
    8 x 8 px: the figures, the picture's folder and each ray's cause."""
    from types import SimpleNamespace

    root = shared_data("real_pair_stratified")
    out = tmp_path_factory.mktemp("measured")
    figures = main([str(root / "reference.tif"), str(root / "distorted.tif"), "--out", str(out)])
    with np.load(out / "measured.npz") as z:
        m = SimpleNamespace(valid=z["valid"], left_out=z["left_out"], displacement=z["displacement_px"])
    return figures, out, m


def test_the_textured_centre_of_a_clipped_background_is_kept(real_pair):
    """Between the first two interfaces (rows 32-46 % of the height, columns 20-80 %) the background sits at 255
    over most pixels and the dark dots carry the texture: at least 95 % of the rays are kept (1.6 % before)."""
    _, _, m = real_pair
    h, w = m.valid.shape
    centre = m.valid[int(0.32 * h):int(0.46 * h), int(0.2 * w):int(0.8 * w)]
    assert centre.mean() >= 0.95, centre.mean()


def test_the_dark_blocks_at_the_bottom_corners_are_left_out(real_pair):
    """Its README: two dark blocks hide the background at the bottom corners (rows 2091-2303, columns 0-227 and
    rows 2079-2254, columns 1572-1719 of the 1720 x 2304 px images): at least 90 % of their rays left out."""
    _, _, m = real_pair
    left, right = m.valid[262:288, 4:28], m.valid[260:282, 197:215]
    assert (~left).mean() >= 0.9 and (~right).mean() >= 0.9, ((~left).mean(), (~right).mean())
    assert (m.left_out[262:288, 4:28] == CAUSES.index("occluded")).mean() >= 0.9  # for the cause the images show


def test_the_picture_and_the_figures_are_written(real_pair):
    figures, out, m = real_pair
    assert (out / "measured.png").stat().st_size > 10_000
    saved = json.loads((out / "measured.json").read_text())
    assert saved["rays"] == [215, 288] and saved["kept"] == pytest.approx(m.valid.mean())
    shares = sum(v for k, v in saved.items() if k.startswith("left_out_"))
    assert saved["kept"] + shares == pytest.approx(1.0)  # every ray kept or left out for one cause
    assert 0 < saved["vector_noise_px"] < 0.5 and saved["measure_time_s"] > 0


def test_bad_pairs_are_one_sentence(tmp_path, capsys):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    cv2.imwrite(str(a), np.zeros((64, 80), np.uint8))
    cv2.imwrite(str(b), np.zeros((64, 96), np.uint8))
    for args, said in (([str(tmp_path / "none.png"), str(b)], "none.png does not exist"),
                       ([str(a), str(b)], "b.png is 96 x 64 px but .*a.png is 80 x 64: a pair is two exposures"),
                       ([str(a), str(a), "--ray-px", "40"], "--ray-px 40: a whole number")):
        with pytest.raises(SystemExit) as e:
            main(args + ["--out", str(tmp_path / "out")])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("nerif.measure: error:") and len(err.strip().splitlines()) == 1
        assert __import__("re").search(said, err), err
