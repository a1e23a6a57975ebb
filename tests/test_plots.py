"""Figures: the slices show the right planes and the error, and they are written as PNG images."""

import cv2
import numpy as np

from nerif.geometry import ProbeBox
from nerif.io.plots import (curves_figure, heldout_figure, profiles_figure, save_figure, sensing_figure,
                             slice_figure)

BOX = ProbeBox((6, 8, 4), 2.0)


def test_slices_show_the_central_xy_plane_and_fixed_heights_with_the_error(tmp_path):
    truth = np.full(BOX.shape, 300.0)
    truth[2, 5, 1] = 1500.0
    rec = truth + 10.0
    fig = slice_figure(rec, BOX, truth, "test")
    axes = [a for a in fig.axes if a.images]  # the panels, without their colour bars
    assert [a.get_title() for a in axes[:3]] == ["reconstruction [K], z = 1.0 mm", "truth [K], z = 1.0 mm",
                                                 "error (rec. - truth) [K], z = 1.0 mm"]
    # horizontal slices at a quarter, half and three quarters of the box's height (y indices 2, 4, 6 of 8),
    # whatever the field: two runs on the same box show the same planes
    assert [a.get_title() for a in axes[3::3]] == [f"reconstruction [K], y = {y:.1f} mm" for y in (-3.0, 1.0, 5.0)]
    np.testing.assert_array_equal(axes[3].images[0].get_array(), rec[:, 2, :].T)
    np.testing.assert_array_equal(axes[2].images[0].get_array(), np.full((8, 6), 10.0))
    assert axes[0].get_ylabel() == "y [mm] (burner axis)" and axes[3].get_xlabel() == "x [mm]"
    img = cv2.imread(str(save_figure(fig, tmp_path / "slices.png")))
    assert img is not None and img.shape[0] > 300 and img.std() > 10


def test_profiles_follow_the_axis_and_cross_it_at_the_slices_heights(tmp_path):
    truth = np.full(BOX.shape, 300.0)
    truth[3, :, 2] = 300.0 + 100.0 * np.arange(8)  # hotter up the axis (x index 3, z index 2 at x = z = 0)
    truth[0, 4, 0] = 2000.0  # the peak off the axis: a profile up its column too
    std = np.full(BOX.shape, 5.0)
    fig = profiles_figure(truth + 20.0, BOX, truth, "p", std=std)
    axial, through, *across = fig.axes
    assert through.get_title() == "vertical through the true peak (x = -5.0, z = -3.0 mm)"
    np.testing.assert_array_equal(through.get_lines()[1].get_ydata(), truth[0, :, 0])
    rec_line, true_line = axial.get_lines()[:2]
    np.testing.assert_array_equal(rec_line.get_xdata(), BOX.axes()[1])
    np.testing.assert_array_equal(true_line.get_ydata(), truth[3, :, 2])
    np.testing.assert_array_equal(rec_line.get_ydata(), truth[3, :, 2] + 20.0)
    assert axial.get_xlabel() == "y [mm]" and axial.get_ylabel() == "T [K]"
    assert [a.get_title() for a in across] == [f"across, y = {y:.1f} mm (z = 1.0 mm)" for y in (-3.0, 1.0, 5.0)]
    assert axial.get_title() == "along the burner axis (x = 1.0, z = 1.0 mm)"  # the voxel column nearest the axis
    np.testing.assert_array_equal(across[0].get_lines()[0].get_ydata(), truth[:, 2, 2] + 20.0)
    on_axis = np.full(BOX.shape, 300.0)
    on_axis[3, 4, 2] = 1000.0
    assert len(profiles_figure(on_axis, BOX).axes) == 4  # a field hottest on the axis: no extra column
    assert [t.get_text() for t in axial.get_legend().get_texts()] == ["reconstruction", "+- 1 std", "truth"]
    assert cv2.imread(str(save_figure(fig, tmp_path / "profiles.png"))) is not None


def test_without_a_truth_only_the_reconstruction_is_shown():
    fig = slice_figure(np.zeros(BOX.shape), BOX, None, unit="sigma")
    panels = [a for a in fig.axes if a.images]
    assert len(panels) == 4 and panels[0].get_title().startswith("reconstruction [sigma]")


def test_curves_heldout_and_sensing_figures_render(tmp_path):
    hist = [{"iteration": i, "wall_time_s": i * 0.1, "temperature_rmse_K": 100.0 / i} for i in (1, 2, 3)]
    fig = curves_figure(hist, [(i, {"loss": 1.0 / i, "loss_discrete": 0.9 / i}) for i in (1, 2, 3)], images_from=2)
    assert fig.axes[1].get_ylabel() == "T RMSE over the probe box [K]"
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]  # each term, the data term in two parts
    assert labels == ["total (sum of the terms)", "data term (discrete gradients): flow deflections",
                      "data term (discrete gradients): images + flow"]
    assert fig.axes[0].get_lines()[0].get_zorder() > fig.axes[0].get_lines()[1].get_zorder()  # the total on top
    one = curves_figure([{"iteration": 5, "wall_time_s": 0.5, "deflection_rmse": 2e-4}], [],
                        deflection_unit="sigma").axes[1]
    assert one.get_ylabel() == "deflection RMSE on training rays [sigma]"
    assert [t.get_text() for t in one.texts][0] == "0.0002 at iteration 5"  # one evaluation is said, not one dot
    obs = np.ones((8, 6, 2))
    obs[0, 0] = np.nan
    fig = heldout_figure(obs, obs * 0.5, "px", "held out", block_px=4)
    panels = [a for a in fig.axes if a.images]
    assert np.nanmax(panels[2].images[0].get_array()) == np.sqrt(2) / 2  # |predicted - observed|
    assert panels[0].get_xlabel() == "column [px]" and panels[0].images[0].get_extent() == [0, 24, 32, 0]
    assert "grey: no ray" in fig._suptitle.get_text()
    u_true = np.zeros((2, 8, 6, 2))
    u_true[1, 6, 2] = 1.0
    fig = sensing_figure(np.zeros((64, 48), np.uint8), np.zeros((64, 48), np.uint8), u_true[1], np.zeros((8, 6, 2)),
                         crop_px=16)
    assert fig.axes[0].images[0].get_array().shape == (16, 16)
    assert cv2.imread(str(save_figure(fig, tmp_path / "s.png"))) is not None


def test_the_sequence_figure_shows_every_frame_s_central_slice_over_its_truth():
    from nerif.io.plots import sequence_figure

    vols = [np.full(BOX.shape, 300.0 + 100 * k) for k in range(3)]
    fig = sequence_figure([(f"frame {k}", v, v + 5.0) for k, v in enumerate(vols)], BOX)
    panels = [a for a in fig.axes if a.images]
    assert len(panels) == 6 and [a.get_title() for a in panels[:3]] == ["frame 0", "frame 1", "frame 2"]
    np.testing.assert_array_equal(panels[1].images[0].get_array(), vols[1][:, :, 2].T)
    np.testing.assert_array_equal(panels[4].images[0].get_array(), vols[1][:, :, 2].T + 5.0)  # its truth, below
    assert len([a for a in sequence_figure([("a", vols[0], None)], BOX).axes if a.images]) == 1  # no truth: one row


def test_the_rig_figure_shows_the_sense_of_the_order_and_the_world_axes_in_each_view(tmp_path):
    """Issue 69: a rig listed in reverse (or turning clockwise) fits the data as well as the true one; the figure
    shows the sense its order turns (from the cameras' positions, counter-clockwise seen from above for nerif's
    arc), and in each view the box and the world's +x and +y where the rig puts them: for the camera on +z, +x
    points to the image's right and +y up (image rows run down), a camera at 90 degrees sees +x come at it."""
    from nerif.geometry.camera import arc_rig
    from nerif.io.plots import rig_figure

    cams = arc_rig(5, 90.0, width_px=64, height_px=96, binning=1)
    box = ProbeBox((20, 30, 20), 1.0)
    pictures = [(np.zeros((96, 64)), "|displacement| [px]")] * 5
    fig = rig_figure(cams, box, {4}, pictures)
    top = fig.axes[0]
    assert top.get_title() == "seen from above: the views in their order turn counter-clockwise"
    reversed_ = rig_figure(cams[::-1], box, {0}, pictures[::-1])
    assert reversed_.axes[0].get_title() == "seen from above: the views in their order turn clockwise"
    first = fig.axes[1]
    arrows = [a for a in first.texts if a.arrow_patch is not None]  # +x then +y, from the box centre
    (x0, y0), (x1, y1) = arrows[0].xyann, arrows[0].xy
    assert x1 - x0 > 5 and abs(y1 - y0) < 1e-6  # +x: to the right
    (x0, y0), (x1, y1) = arrows[1].xyann, arrows[1].xy
    assert y1 - y0 < -5 and abs(x1 - x0) < 1e-6  # +y: up the image
    side = [a for a in fig.axes[5].texts if a.arrow_patch is not None][0]  # camera 4, at 90 degrees, on +x
    assert np.hypot(*np.subtract(side.xy, side.xyann)) < 1e-6  # +x along its line of sight
    assert fig.axes[5].get_title() == "camera 04, held out"
    img = cv2.imread(str(save_figure(fig, tmp_path / "rig.png")))
    assert img is not None and img.std() > 10


def test_figures_placed_by_margins_keep_every_label_colour_bar_and_legend_inside_the_picture():
    """The profiles, curves, held-out and rig figures are placed with margins in inches, not by a layout that measures
    their labels: on shapes a run meets (a tall and a wide view, a 9-view rig, a long legend), every axes' extent with
    its tick labels, titles, colour bars, legend and annotations lies within the figure, and no two panels' (with their
    labels and annotations) overlap."""
    from matplotlib.transforms import Bbox

    from nerif.geometry.camera import arc_rig
    from nerif.io.plots import rig_figure

    box = ProbeBox((30, 50, 30), 2.0)
    T = 300.0 + 1500.0 * np.exp(-((np.indices(box.shape) - 12.0) ** 2).sum(0) / 40.0)
    hist = [{"iteration": 100 * i, "wall_time_s": 4.0 * i, "temperature_rmse_K": 40.0 / i} for i in range(1, 19)]
    terms = {"loss": 1.0, "loss_discrete": 1.0, "loss_boundary": 1e-4, "loss_tv": 1e-3}
    cams = arc_rig(9, 160.0, width_px=240, height_px=320, binning=8)
    u = np.random.default_rng(0).normal(size=(40, 30, 2))
    figures = {"profiles": profiles_figure(T, box, T + 5.0, "a title", std=np.full(box.shape, 9.0)),
               "curves": curves_figure(hist, [(i, terms) for i in range(1, 1800, 10)], 1200, "rad"),
               "curves, a wider legend": curves_figure(hist, [(i, {k: terms[k] for k in list(terms)[:3]})
                                                              for i in range(1, 1800, 10)], 1200, "rad"),
               "held out, tall": heldout_figure(u, u + 0.1, "px", "camera 4", block_px=8),
               "held out, wide": heldout_figure(u.transpose(1, 0, 2) * 1e3, u.transpose(1, 0, 2) * 1e3, "px",
                                                "camera 4", block_px=8),
               "rig": rig_figure(cams, box, {8}, [(np.linalg.norm(u, axis=-1), "|displacement| [px]")] * 9),
               "rig, no pictures": rig_figure(cams, box, {8}, [None] * 9)}
    for name, fig in figures.items():
        renderer = fig.canvas.get_renderer()
        page = Bbox.from_bounds(0, 0, *fig.canvas.get_width_height()).padded(1.0)
        extents = [ax.get_tightbbox(renderer) for ax in fig.axes]
        for ax, e in zip(fig.axes, extents):
            assert page.containsx(e.x0) and page.containsx(e.x1) and page.containsy(e.y0) and page.containsy(e.y1), (
                name, ax.get_title() or ax.get_label(), e.bounds, page.bounds)
        for ax in fig.axes:  # a legend below its panel may reach under the next one's labels: not an overlap of theirs
            if ax.get_legend() is not None:
                ax.get_legend().set_in_layout(False)
        panels = [ax.get_tightbbox(renderer) for ax in fig.axes if ax.get_label() != "<colorbar>"]
        for a in range(len(panels)):
            for b in range(a + 1, len(panels)):
                inter = Bbox.intersection(panels[a], panels[b])
                assert inter is None or inter.width * inter.height < 0.02 * min(
                    panels[a].width * panels[a].height, panels[b].width * panels[b].height), (name, a, b)
