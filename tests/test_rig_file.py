"""The rig file (:mod:`nerif.data.rig_file`): what the writer writes the reader reads back value for value, an
edited file is read again, and each malformed key is one sentence naming the file and the key."""
import os

import pytest
import yaml

from nerif.data.rig_file import ArcLens, exposures, read_rig, write_rig
from nerif.geometry import ProbeBox
from nerif.physics import Ambient

ARC = {"camera": {"focal_mm": 105.0, "pitch_um": 40.0, "sensor_px": [36, 64], "f_number": 32.0,
                  "camera_to_centre_mm": 800.0, "camera_to_background_mm": 1600.0},
       "views": {"angles_deg": [0.0, 40.0, 80.0, 120.0], "images": [f"d{v}.png" for v in range(4)],
                 "references": "ref.png"},
       "roi_px": [2, 4, 30, 56]}


def written(tmp_path, **edits):
    box, amb = ProbeBox((6, 10, 6), 2.0), Ambient(T0=293.0, n0=1.00028, T_max=2100.0)
    write_rig(tmp_path, ARC, box, amb, heldout=[3])
    if edits:
        rig = yaml.safe_load((tmp_path / "rig.yaml").read_text())
        for dotted, value in edits.items():
            *parents, last = dotted.split("__")
            node = rig
            for p in parents:
                node = node[p]
            node[last] = value
        (tmp_path / "rig.yaml").write_text(yaml.safe_dump(rig))
    return tmp_path


def test_what_the_writer_writes_comes_back_value_for_value(tmp_path):
    rig = read_rig(written(tmp_path))
    assert rig.version == 2 and rig.sensor_px == (36, 64) and rig.angles_deg == (0.0, 40.0, 80.0, 120.0)
    assert rig.lens == ArcLens(105.0, 40.0, 32.0, 800.0, 1600.0) and rig.calibrated is None
    assert rig.roi_px == (2, 4, 30, 56) and rig.heldout == (3,)
    assert rig.box.shape == (6, 10, 6) and rig.box.voxel_mm == 2.0
    assert (rig.ambient.T0, rig.ambient.n0) == (293.0, 1.00028) and rig.temperature_range_K == (293.0, 2100.0)
    assert [exposures(r) for r in rig.references] == [("ref.png",)] * 4  # one shared reference, per view
    assert len(rig.frames) == 1 and rig.frames[0].images == tuple(f"d{v}.png" for v in range(4))


def test_an_edited_rig_file_is_read_again(tmp_path):
    root = written(tmp_path)
    assert read_rig(root) is read_rig(root)  # read once while the file stays as it was
    text = (root / "rig.yaml").read_text().replace("heldout: [3]", "heldout: [1]")
    (root / "rig.yaml").write_text(text + "\n")
    os.utime(root / "rig.yaml", ns=(1, 10**18))
    assert read_rig(root).heldout == (1,)


@pytest.mark.parametrize("edits, message", [
    ({"format": "other"}, "is not a nerif capture rig file"),
    ({"version": 7}, "has version 7; this nerif reads versions 1, 2 and 3"),
    ({"views__angles_deg": "0, 40"}, "views.angles_deg = '0, 40' must be a list of numbers"),
    ({"views__references": ["r0.png", "r1.png"]}, "views.references lists 2 files for 4 views"),
    ({"roi_px": [0, 0, 30]}, "roi_px \\(x, y, width, height\\)"),
    ({"temperature_range_K": [2000, 300]}, "must be two increasing positive temperatures"),
    ({"probe__shape": [6, 0, 6]}, "probe.shape = \\[6, 0, 6\\] must be three positive voxel counts"),
    ({"ambient__T0": 25.0}, "ambient.T0 = 25.0 is not a temperature in kelvin"),
    ({"camera__camera_to_background_mm": 500.0}, "camera.camera_to_background_mm = 500.0 must exceed"),
    ({"colour": "blue"}, "unknown key 'colour'"),
])
def test_a_malformed_key_is_one_sentence_naming_the_file_and_the_key(tmp_path, edits, message):
    root = written(tmp_path, **edits)
    with pytest.raises(ValueError, match=message) as e:
        read_rig(root)
    assert str(root / "rig.yaml") in str(e.value) and "\n" not in str(e.value)


def test_a_folder_without_a_rig_file_says_what_it_needs(tmp_path):
    with pytest.raises(FileNotFoundError, match="a capture folder needs a rig.yaml beside its images"):
        read_rig(tmp_path)
