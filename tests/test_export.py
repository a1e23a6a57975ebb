"""Atomic writes, ParaView volumes."""
import base64
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from nerif.export import atomic_write, write_json, write_vti


def test_vti_holds_the_volume_x_fastest(tmp_path):
    vol = np.random.rand(3, 4, 5).astype(np.float32)
    write_vti(tmp_path / "v.vti", 0.5, [-0.5, -0.75, -1.0], T=vol)
    root = ET.parse(tmp_path / "v.vti").getroot()
    img = root.find("ImageData")
    assert img.get("WholeExtent") == "0 2 0 3 0 4" and img.get("Spacing") == "0.5 0.5 0.5"
    raw = base64.b64decode(img.find("Piece/PointData/DataArray").text)
    n = np.frombuffer(raw[:4], "<u4")[0]
    data = np.frombuffer(raw[4:4 + n], "<f4").reshape(5, 4, 3)  # z slowest
    np.testing.assert_array_equal(data.transpose(2, 1, 0), vol)


def test_the_volumes_say_their_units_in_vti_field_data_and_npz(tmp_path):
    """Issue 50: VTK's string field data (each string's bytes, 0-terminated, as vtkXMLImageDataWriter writes them)
    and an ``units`` entry of the ``.npz``."""
    import json

    from nerif.export import write_npz
    from nerif.units import VOLUMES

    vol = np.zeros((2, 3, 4))
    write_vti(tmp_path / "v.vti", 0.5, [0, 0, 0], units=VOLUMES, T=vol, sigma=vol)
    root = ET.parse(tmp_path / "v.vti").getroot()
    field = root.find("ImageData/FieldData/Array")
    assert field.get("Name") == "units" and field.get("type") == "String" and field.get("NumberOfTuples") == "3"
    words = bytes(int(c) for c in field.text.split()).split(b"\0")[:-1]
    assert [w.decode() for w in words] == ["T: K", f"sigma: {VOLUMES['sigma']}", "lengths: mm"]
    assert [a.get("units") for a in root.iter("DataArray")] == ["K", VOLUMES["sigma"]]
    write_npz(tmp_path / "v.npz", units=VOLUMES, T=vol, voxel_mm=0.5)
    assert json.loads(str(np.load(tmp_path / "v.npz")["units"])) == {"T": "K", "voxel_mm": "mm"}


def test_atomic_write_leaves_the_old_file_on_failure(tmp_path):
    p = tmp_path / "metrics.json"
    write_json({"a": 1}, p)

    def broken(tmp):
        with open(tmp, "w") as f:
            f.write("{half")
        raise RuntimeError("crash while writing")

    with pytest.raises(RuntimeError):
        atomic_write(p, broken)
    assert json.loads(p.read_text()) == {"a": 1}
    assert [q.name for q in tmp_path.iterdir()] == ["metrics.json"]


def test_written_files_get_the_usual_permissions_not_the_temporary_files_private_ones(tmp_path):
    import os
    import stat

    old = os.umask(0o022)
    try:
        p = atomic_write(tmp_path / "a.txt", lambda t: open(t, "w").write("x"))
    finally:
        os.umask(old)
    assert stat.S_IMODE(p.stat().st_mode) == 0o644 and p.read_text() == "x"


def test_pvd_lists_each_dataset_with_its_time(tmp_path):
    from nerif.export import write_pvd

    path = write_pvd(tmp_path / "s.pvd", [(0.0, "frame_0000/reconstruction.vti"), (0.004, "frame_0001/reconstruction.vti")])
    root = ET.parse(path).getroot()
    assert root.get("type") == "Collection"
    sets = root.find("Collection").findall("DataSet")
    assert [(float(d.get("timestep")), d.get("file")) for d in sets] == [
        (0.0, "frame_0000/reconstruction.vti"), (0.004, "frame_0001/reconstruction.vti")]
