"""The per-voxel uncertainty (nerif/solvers/uncertainty.py) and its scores (nerif.metrics.uncertainty_scores)."""
import numpy as np
import pytest
import torch

from nerif.metrics import ause, uncertainty_scores
from nerif.solvers.uncertainty import UNCERTAINTY, Estimate, calibration, left_out_views
from nerif.units import unit_of


def test_members_leave_out_different_views_all_round():
    assert left_out_views(9, 4, 1) == [[0], [2], [4], [6]]
    two = left_out_views(10, 5, 2)
    assert all(len(out) == 2 and out[1] - out[0] == 5 for out in two)  # opposite sides of the arc
    assert len({v for out in two for v in out}) == 10  # every view left out once


def test_calibration_scales_the_spread_to_the_residual_less_the_noise():
    """Members spread with unit variance per component around the fit, the field's residual has variance 4 on the
    rays through the flame and the measurement's noise (0.5 per component) everywhere: the factor that makes the
    spread explain the error beyond the noise is sqrt((4 + 0.25 - 0.25) / 1) = 2."""
    g = torch.Generator().manual_seed(0)
    n, k = 40000, 8
    fit = torch.zeros(2 * n, 3, dtype=torch.float64)
    fit[:n] = 10.0  # the flame's rays; the others see none
    noise = 0.5 * torch.randn(2 * n, 3, generator=g, dtype=torch.float64)
    error = torch.zeros_like(fit)
    error[:n] = 2.0 * torch.randn(n, 3, generator=g, dtype=torch.float64)
    observed = fit + error + noise
    members = fit + torch.randn(k, 2 * n, 3, generator=g, dtype=torch.float64)
    assert calibration(fit, members, observed) == pytest.approx(2.0, rel=0.03)


def test_scores_of_a_true_standard_deviation():
    """Errors drawn with a known, varying standard deviation: coverages are a Gaussian's, the rank correlation is
    positive, and AUSE is smaller than that of an uninformative one (and 0 for the error itself)."""
    rng = np.random.default_rng(0)
    truth = np.zeros((40, 40, 40))
    truth[5:35, 5:35, 5:35] = -np.linspace(0.1, 1.0, 30)[None, None, :]
    std = 0.01 + 0.05 * rng.random(truth.shape)
    sigma = truth + std * rng.standard_normal(truth.shape)
    s = uncertainty_scores(sigma, std, truth)
    assert s["coverage_1sigma"] == pytest.approx(0.683, abs=0.01)
    assert s["coverage_2sigma"] == pytest.approx(0.954, abs=0.01)
    assert s["spearman"] > 0.3
    flame = np.abs(truth) > 0.05
    err = np.abs(sigma - truth)[flame]
    assert ause(err, err) == pytest.approx(0.0, abs=1e-12)
    assert s["ause"] < ause(err, rng.random(err.shape)) - 0.1
    # a random order's expected AUSE, in closed form, is what a shuffled one reaches
    assert ause(err, rng.random(err.shape)) == pytest.approx(s["ause_random"], abs=0.02)
    assert s["calibration_error"] < 0.01  # Gaussian errors of these widths: every nominal level met
    assert uncertainty_scores(sigma, std, np.zeros_like(truth)) == {}  # no flame: nothing to score


def test_the_calibration_error_of_a_band_too_wide_or_too_narrow_is_the_gap_a_gaussian_gives():
    """Errors of unit Gaussians scored against twice or half that width: at each nominal level p the observed
    coverage is P(|N| <= k z_p), so the mean gap is known in closed form."""
    from scipy.stats import norm

    from nerif.metrics import CALIBRATION_LEVELS, calibration_error

    err = np.abs(np.random.default_rng(1).standard_normal(400000))
    p = np.asarray(CALIBRATION_LEVELS)
    z = norm.ppf((1 + p) / 2)
    for k in (2.0, 0.5):
        expected = np.abs((2 * norm.cdf(k * z) - 1) - p).mean()
        assert calibration_error(err, np.full_like(err, k)) == pytest.approx(expected, abs=0.003)
    assert calibration_error(err, np.ones_like(err)) < 0.003


def test_ensemble_settings_are_checked_in_one_sentence():
    for bad, match in (({"members": 1}, "members=1"), ({"fraction": 0.0}, "fraction=0.0"),
                       ({"leave_out": 0}, "leave_out=0"), ({"lr_factor": 2.0}, "lr_factor=2.0"),
                       ({"perturb": -1.0}, "perturb=-1.0")):
        with pytest.raises(ValueError, match=match):
            UNCERTAINTY.build({"name": "ensemble", **bad})


def test_a_larger_error_on_the_held_out_views_widens_the_band():
    """Noisier data leave a larger error in the field, which the held-out views show beyond their noise: the factor
    grows with it (doubled here), the members' spread alike. On the flame families, noise 0.2 widens the median T
    uncertainty by 24-29 % (benchmarks/uncertainty.py)."""
    g = torch.Generator().manual_seed(1)
    n = 20000
    fit = torch.full((n, 3), 5.0, dtype=torch.float64)
    members = fit + torch.randn(4, n, 3, generator=g, dtype=torch.float64)
    factors = [calibration(fit, members, fit + e * torch.randn(n, 3, generator=g, dtype=torch.float64))
               for e in (1.0, 2.0)]
    assert factors[1] / factors[0] == pytest.approx(2.0, rel=0.05)


@pytest.fixture(scope="module")
def family_run(tmp_path_factory):
    """A flame of the plumes family (rendered by quadrature, independently of nerif's forward model; 9 views and 2
    held out) reconstructed with a small ensemble."""
    from dataclasses import replace

    from nerif.app import run
    from nerif.configs import compose
    from nerif.data.families import FAMILIES, write_dataset
    from nerif.geometry import ProbeBox

    root = tmp_path_factory.mktemp("family")
    flame = replace(FAMILIES["plumes"](1), box=ProbeBox((30, 50, 30), 2.0))
    overrides = write_dataset(root / "data", flame, binning=16)
    cfg = compose(overrides + ["data.binning=1", "data.pitch_um=320", "train.progress=false", "device=cpu",
                               "data_term=flow", "train.iterations=100", "train.rays_per_batch=256",
                               "sampler.samples_per_ray=16", "field.log2_table_size=12", "uncertainty=ensemble",
                               "uncertainty.members=2", "uncertainty.fraction=0.5"])
    return run(cfg, root / "run"), root / "run"


def test_the_outputs_carry_the_uncertainty(family_run):
    m, folder = family_run
    with np.load(folder / "reconstruction.npz") as z:
        for key in ("sigma_std", "T_std", "views_seeing"):
            assert z[key].shape == z["sigma"].shape and np.isfinite(z[key]).all()
        assert (z["sigma_std"] >= 0).all() and z["sigma_std"].max() > 0
        assert z["views_seeing"].max() == 9  # every training view reaches the flame
    text = (folder / "reconstruction.vti").read_bytes()
    assert b'Name="sigma_std"' in text and b'Name="T_std"' in text
    assert m["uncertainty_scale_from"] == "held-out views" and m["T_std_median_flame_K"] > 0
    assert m["T_std_at_peak_K"] > 0 and abs(m["T_peak_K"] - 300.0) > 100
    # issue 59: the reported figures' intervals hold the figures themselves, and are scored against the truth
    lo, hi = m["T_peak_interval_K"]
    assert lo < m["T_peak_K"] < hi
    assert all(a <= c <= b for (a, b), c in zip(m["T_peak_position_interval_mm"], m["T_peak_position_mm"]))
    least, most = m["flame_volume_interval_cm3"]
    assert least <= m["flame_volume_cm3"] <= most
    for key in ("T_peak_in_interval", "T_peak_position_in_interval", "flame_volume_in_interval"):
        assert m[key] in (0.0, 1.0) and unit_of(key) is not None


def test_coverage_and_correlation_on_a_known_truth(family_run):
    """Bounds on a small flame (two members only: their spread is a rough estimate): the 2-sigma band holds the
    truth in most of the flame, and over the box the uncertainty is larger where the error is (the flame against
    the ambient gas the hull pins)."""
    from scipy.stats import spearmanr

    m, folder = family_run
    assert 0.5 <= m["uncertainty_coverage_2sigma"] <= 0.995, m["uncertainty_coverage_2sigma"]
    with np.load(folder / "reconstruction.npz") as z:
        truth = ((z["n0"] - 1) * z["T0"] / z["T_true"] - (z["n0"] - 1)) / z["delta_thre"]
        assert spearmanr(z["sigma_std"].ravel(), np.abs(z["sigma"] - truth).ravel())[0] > 0.2


def test_a_voxel_no_ray_reaches_is_less_certain_than_one_every_view_sees_and_the_result_is_unchanged():
    """The upper half of the box hidden from every view (no 3-D mask): there the data say nothing, and the standard
    deviation is at least the prior's; where every view looks it is the members' calibrated spread. The members
    leave the solver's result as it was."""
    from tests.helpers import trained_on_half_the_box

    s, scene = trained_on_half_the_box()
    before = s.reconstruction()
    out = UNCERTAINTY.build({"name": "ensemble", "members": 2, "fraction": 0.5})(s)
    np.testing.assert_array_equal(s.reconstruction(), before)
    seen, std = out.volumes["views_seeing"], out.volumes["sigma_std"]
    assert (seen == 0).any() and (seen == seen.max()).any()
    assert np.median(std[seen == 0]) > 10 * np.median(std[seen == seen.max()])
    assert out.report["uncertainty_scale_from"] == "held-out views"
    assert not [k for k in out.report if unit_of(k) is None]  # every figure it reports has its unit


def test_a_run_without_uncertainty_writes_none(tmp_path):
    from nerif.app import run
    from tests.helpers import tiny_config

    m = run(tiny_config("train.iterations=2", "uncertainty=auto"), tmp_path)  # the default, without a held-out view
    assert "uncertainty_scale" not in m and "T_std_median_flame_K" not in m
    with np.load(tmp_path / "reconstruction.npz") as z:
        assert "sigma_std" not in z and "T_std" not in z


def test_a_solver_without_members_is_refused_before_training(tmp_path):
    from nerif.app import run
    from tests.helpers import tiny_config

    with pytest.raises(ValueError, match="uncertainty=ensemble needs a trained field to start its members from: "
                                         "solver=cgls has no trained field"):
        run(tiny_config("solver=cgls", "uncertainty=ensemble"), tmp_path)


def test_the_default_estimates_an_ensemble_only_where_the_run_can_calibrate_one(caplog):
    """``uncertainty=auto`` (the default): the ensemble's members, with its settings, where a neural solver's data
    hold a view out and its training views spare one a member; else no uncertainty, said in the log, never a
    refusal (a run on data without a held-out view goes on as it was)."""
    import logging
    from dataclasses import replace
    from types import SimpleNamespace

    from tests.helpers import trained_on_half_the_box

    s, scene = trained_on_half_the_box()
    settings = {"members": 2, "fraction": 0.5}
    auto = UNCERTAINTY.build({"name": "auto", **settings})
    auto.check(s)
    out = auto(s)
    ens = UNCERTAINTY.build({"name": "ensemble", **settings})(s)
    assert out.report["uncertainty_scale_from"] == "held-out views"
    np.testing.assert_allclose(out.volumes["sigma_std"], ens.volumes["sigma_std"], rtol=1e-4, atol=1e-7)
    s.scene = replace(scene, heldout=None)
    with caplog.at_level(logging.INFO, logger="nerif.solvers.uncertainty"):
        assert auto(s) == Estimate()
    assert "the data hold no view out" in caplog.text and "no uncertainty estimated" in caplog.text
    s.scene = scene
    assert "cannot spare 9" in UNCERTAINTY.build({"name": "auto", "leave_out": 9}).without(s)
    voxel = SimpleNamespace(name="cgls", scene=scene)  # no trained field (nerif.solvers.trained)
    auto.check(voxel)  # no refusal
    assert auto.without(voxel) == "solver=cgls has no trained field"


def test_the_default_takes_the_ensembles_settings_from_its_file():
    from nerif.configs import compose

    auto, ens = compose([]).uncertainty, compose(["uncertainty=ensemble"]).uncertainty
    assert auto.name == "auto" and ens.name == "ensemble"
    assert {k: v for k, v in auto.items() if k != "name"} == {k: v for k, v in ens.items() if k != "name"}
