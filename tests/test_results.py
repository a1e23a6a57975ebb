"""A finished run's results (:mod:`nerif.results`): computed before anything is written, from the solver's own
evaluation and volumes; the uncertainty's figures over the flame."""
from types import SimpleNamespace

import numpy as np
import pytest

from nerif.metrics import temperature_std
from nerif.physics import Ambient
from nerif.results import Results, final_volumes, results, uncertainty_report
from nerif.solvers.uncertainty import Estimate

AMB = Ambient(T0=300.0, n0=1.00027, T_max=2000.0)


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


def test_the_results_of_a_trained_field_are_its_volumes_its_evaluation_and_its_held_out_views():
    """The tiny scene with its upper half hidden and view 5 held out, trained 40 steps: the volumes are the solver's
    sigma and what follows from it (T, n, delta, the truth), the figures its last evaluation's and every held-out
    ray's (not the evaluation subset's), and the held-out view's pictures its observed and predicted displacements."""
    from tests.helpers import trained_on_half_the_box

    solver, scene = trained_on_half_the_box(40)
    vols = final_volumes(solver, scene, Estimate())
    sigma = solver.reconstruction()
    np.testing.assert_array_equal(vols["sigma"], sigma)
    amb = scene.ambient  # air: n - 1 = T0 (n0 - 1) / T, delta = n / n0 - 1 = sigma delta_thre
    np.testing.assert_allclose((vols["n"] - 1) * vols["T"], amb.T0 * (amb.n0 - 1), rtol=1e-9)
    np.testing.assert_allclose(vols["delta"], vols["n"] / amb.n0 - 1, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(vols["delta"], sigma * amb.delta_thre, rtol=1e-12)
    np.testing.assert_array_equal(vols["T_true"], scene.truth_T)
    found = results(solver, scene, vols, Estimate(), flame_above_K=1000.0, figures=True)
    assert isinstance(found, Results) and found.volumes is vols
    m = found.metrics
    last = {k: v for k, v in solver.history[-1].items() if k != "iteration" and not k.startswith("heldout")}
    assert {k: m[k] for k in last} == last  # the last evaluation's figures, as evaluated
    every = solver.evaluation.heldout_errors(solver.predict, every=True)
    assert m["heldout_deflection_rmse"] == pytest.approx(every["heldout_deflection_rmse"])
    assert m["iterations"] == 40 and m["T_peak_field_K"] == pytest.approx(float(vols["T"].max()))
    assert [v.camera.name for v in found.heldout] == [c.name for c in scene.heldout.cameras]
    view = found.heldout[0]
    assert found.heldout_unit == "px" and view.observed.shape == view.predicted.shape and view.observed.shape[-1] == 2
    assert results(solver, scene, vols, Estimate(), flame_above_K=1000.0, figures=False).heldout == []


def test_a_rig_that_leaves_more_directions_unseen_than_seen_bounds_the_peak_by_the_prior_alone():
    """Issue 66: 7 views over 90 degrees less one held out at an end (a 105 degree gap) read a 1986 K core at 1086
    K, beyond any spread of its members: the peak's interval then reaches the prior's hottest; 12 views over 165
    degrees keep the interval the field's spread gives."""
    from nerif.geometry import ProbeBox
    from nerif.geometry.camera import arc_rig
    from nerif.results import peak_and_uncertainty

    box = ProbeBox((17, 17, 17), 1.0)
    g = np.meshgrid(*[np.arange(17) - 8] * 3, indexing="ij")
    sigma = float(AMB.sigma_from_temperature(1500.0)) * np.exp(-sum(x**2 for x in g) / (2 * 4.0**2))
    std = np.full(box.shape, 0.01)
    vols = {"sigma": sigma, "sigma_std": std, "T": AMB.temperature_from_sigma(sigma),
            "T_std": temperature_std(AMB, sigma, std)}
    solver = SimpleNamespace(interval=(-1.05, 0.05), cell_mm=1.5)
    hot = {}
    for n, span in ((12, 165.0), (6, 75.0)):
        scene = SimpleNamespace(ambient=AMB, box=box, ray_spacing_mm=1.0, displacements=object(), truth_T=None,
                                cameras=arc_rig(n, span))
        hot[n] = peak_and_uncertainty(solver, scene, vols, 1000.0, [])["T_peak_interval_K"][1]
    assert hot[6] == pytest.approx(float(AMB.temperature_from_sigma(np.float64(-1.05))))
    assert 1500.0 < hot[12] < 0.8 * hot[6]
