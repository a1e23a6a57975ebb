"""An opaque burner tube in the realistic chain's views (:mod:`nerif.sensing.burner`)."""
from nerif.geometry import RIGS
from nerif.sensing.burner import burner_pixels


def test_the_tubes_pixels_are_a_band_below_its_top_as_a_pinhole_projects_it():
    """A tube of radius 6 mm on the axis, its top at y = -16 mm, seen by the paper's arc camera (800 mm away, the
    images 8 x 8 binned): a band about the middle column, 12 mm wide at the axis (a little wider below, nearer the
    camera), starting at the row of y = -16 mm under the centre row."""
    cam = RIGS.build({"name": "arc", "n_cameras": 2, "binning": 8})[0]  # 90 x 160 px of 160 um
    tube = burner_pixels(cam, 6.0, -16.0)
    px_per_mm = cam.image_distance_mm / 800.0 / cam.pitch_mm  # at the axis, 800 mm from the camera
    rows = tube.any(1)
    assert abs(tube.sum(1)[rows].min() - 12.0 * px_per_mm) <= 2.0 and tube.sum(1)[-1] >= 12.0 * px_per_mm - 2
    assert abs(int(rows.argmax()) - (cam.height / 2 + 16.0 * px_per_mm)) <= 2.0
    assert not tube[: cam.height // 2].any()  # nothing above the centre row
    assert not burner_pixels(cam, 6.0, -400.0).any()  # a tube whose top is below the view
