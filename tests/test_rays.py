"""Camera rays through the probe box."""
import numpy as np
import pytest

from nerif.geometry import Camera, ProbeBox, arc_rig, look_at_origin, rays_in_box


def test_a_camera_that_does_not_see_the_box_is_named():
    box = ProbeBox((10, 10, 10), 1.0)
    good = arc_rig(n_cameras=1, binning=40)[0]
    pos = np.array([0.0, 0.0, 800.0])
    away = Camera(pos, look_at_origin(-pos) @ np.diag([1.0, 1.0, 1.0]), 112.4, 0.8, 18, 32, 32.0, 1600, 105,
                  name="camera 7 (backwards)")
    with pytest.raises(ValueError, match="camera 7 \\(backwards\\) .* does not see the probe box"):
        rays_in_box(box, [good, away])
