"""The run's writers (:mod:`nerif.io.outputs`): camera names as files and places, ``rig.png`` written with every
view in the rig's order, and a run's results written as they were computed."""
from types import SimpleNamespace

import numpy as np
import pytest

from nerif.io.outputs import camera_file, rig_index


@pytest.mark.parametrize("name, file, index", [("camera 8 (160.0 deg)", "camera08", 8),
                                               ("camera 03 (60.0 deg)", "camera03", 3),
                                               ("left cam #2", "left_cam_2", 5)])
def test_camera_names_as_files_and_as_places_in_the_rig(name, file, index):
    assert camera_file(name) == file and rig_index(name, 5) == index


def test_rig_png_holds_every_view_in_the_rigs_order_with_the_held_out_one(tmp_path, monkeypatch):
    """Training views then held-out ones in a scene; the figure draws them in the rig's order (by their names), the
    held-out one marked at its place, each with its displacement magnitude."""
    import cv2

    import nerif.io.outputs as outputs
    from nerif.geometry import ProbeBox
    from nerif.geometry.camera import arc_rig
    from nerif.io.outputs import write_rig

    drawn = {}

    def spy(cameras, box, heldout, pictures, title=""):
        drawn.update(names=[c.name for c in cameras], heldout=heldout, pictures=pictures)
        return real(cameras, box, heldout, pictures, title)

    real = outputs.rig_figure
    monkeypatch.setattr(outputs, "rig_figure", spy)

    cams = arc_rig(4, 120.0, width_px=48, height_px=64, binning=1)
    view = lambda c: SimpleNamespace(camera=c, measured_px=np.ones((64, 48, 2), np.float32))  # noqa: E731
    held = SimpleNamespace(views=[view(cams[1])])
    scene = SimpleNamespace(views=[view(c) for c in (cams[0], cams[2], cams[3])], heldout=held, n_views=3,
                            box=ProbeBox((10, 16, 10), 2.0))
    write_rig(scene, tmp_path)
    assert drawn["names"] == [c.name for c in cams] and drawn["heldout"] == {1}
    np.testing.assert_allclose(drawn["pictures"][2][0], np.sqrt(2.0))
    img = cv2.imread(str(tmp_path / "rig.png"))
    assert img is not None and img.shape[1] > img.shape[0] > 300
