"""The run's writers (:mod:`nerif.io.outputs`): a temperature's standard deviation carried from sigma's, the
uncertainty figures over the flame, camera names as files and places, and ``rig.png`` written with every view in
the rig's order."""
from types import SimpleNamespace

import numpy as np
import pytest

from nerif.io.outputs import camera_file, rig_index, temperature_std, uncertainty_report
from nerif.physics import Ambient

AMB = Ambient(T0=300.0, n0=1.00027, T_max=2000.0)


def test_a_temperatures_standard_deviation_is_sigmas_times_the_slope_of_t():
    """Air, sigma = -1 at T_max: T = T0 / (1 + k sigma), k = 1 - T0 / T_max, so |dT/dsigma| = T0 k / (1 + k sigma)^2."""
    sigma, std = np.array([-0.9, -0.5, 0.0]), np.array([0.01, 0.02, 0.03])
    k = 1 - AMB.T0 / AMB.T_max
    slope = AMB.T0 * k / (1 + k * sigma) ** 2
    np.testing.assert_allclose(AMB.temperature_from_sigma(sigma), AMB.T0 / (1 + k * sigma), rtol=1e-6)
    np.testing.assert_allclose(temperature_std(AMB, sigma, std), slope * std, rtol=1e-6)


def test_the_uncertainty_figures_are_medians_over_the_flame_and_the_peaks_own():
    sigma = np.zeros((5, 5, 5))
    sigma[2, 2, 2], sigma[1, 2, 2] = -0.9, -0.3  # the flame: |sigma| above 5 % of its peak
    std = np.full(sigma.shape, 0.5)
    std[2, 2, 2], std[1, 2, 2] = 0.01, 0.03
    T = AMB.temperature_from_sigma(sigma)
    vols = {"sigma": sigma, "sigma_std": std, "T": T, "T_std": temperature_std(AMB, sigma, std)}
    out = uncertainty_report(vols, SimpleNamespace(truth_T=None, ambient=AMB))
    assert out["sigma_std_median_flame"] == pytest.approx(0.02)  # the two flame voxels, not the 0.5 outside
    assert out["T_std_at_peak_K"] == pytest.approx(float(vols["T_std"][2, 2, 2]))
    assert "uncertainty_coverage_2std" not in out and not any(k.startswith("uncertainty_") for k in out)


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
