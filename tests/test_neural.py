"""The neural solver: exact resume, divergence, checks of its settings, ray draws, what it trains on."""
import warnings

import numpy as np
import pytest
import torch

from nerif.configs import group
from nerif.data import DATASETS
from nerif.masks import MASKS
from nerif.metrics import rmse
from nerif.renderers import GRADIENTS
from nerif.solvers import SOLVERS, DivergenceError
from tests.helpers import solver, tiny_config


def neural_solver(*overrides, masks=None):
    """The tiny scene's neural solver (no masks unless given), its weights drawn under seed 0."""
    cfg = tiny_config(*overrides)
    scene = DATASETS.build(group(cfg, "data"))
    torch.manual_seed(0)
    return solver(cfg, scene, masks)


def test_resuming_a_checkpoint_continues_exactly(tmp_path):
    straight = neural_solver()
    for _ in range(12):
        straight.step()
    first = neural_solver()
    for _ in range(6):
        first.step()
    first.save(tmp_path / "ck.pt")
    resumed = neural_solver()
    resumed.load(tmp_path / "ck.pt")
    assert resumed.iteration == 6
    for _ in range(6):
        resumed.step()
    for a, b in zip(straight.field.parameters(), resumed.field.parameters()):
        torch.testing.assert_close(a, b)
    assert int(resumed.optimisation.average.n_averaged) == 12
    for a, b in zip(straight.optimisation.average.parameters(), resumed.optimisation.average.parameters()):
        torch.testing.assert_close(a, b)


def test_a_resume_with_more_iterations_continues_the_schedule_as_if_planned_so(tmp_path):
    """Issue 28: a resume from 50 to 120 iterations restarted the cosine schedule at its peak (or, continued
    as it was, would have held it at its floor): it goes on as the longer run's own schedule."""
    short = neural_solver("train.iterations=10")
    for _ in range(10):
        short.step()
    short.save(tmp_path / "ck.pt")
    longer = neural_solver("train.iterations=20")
    longer.load(tmp_path / "ck.pt")
    straight = neural_solver("train.iterations=20")
    for _ in range(10):
        straight.step()
    assert longer.optimisation.lr == pytest.approx(straight.optimisation.lr, rel=1e-9)
    assert longer.optimisation.lr == pytest.approx(5e-3 / 2, rel=1e-3)  # half-way down the cosine
    for _ in range(10):
        longer.step()
        straight.step()
        assert longer.optimisation.lr == pytest.approx(straight.optimisation.lr, rel=1e-6)


def test_a_checkpoint_without_an_average_resumes_and_averages_from_the_next_step(tmp_path):
    """A checkpoint of a nerif before ``train.ema_decay`` holds no average: the run resumes, its outputs are the
    trained field's until the next step, whose weights the average then starts from."""
    tr = neural_solver()
    for _ in range(3):
        tr.step()
    st = tr.state_dict()
    del st["average"]
    torch.save(st, tmp_path / "old.pt")
    resumed = neural_solver()
    resumed.load(tmp_path / "old.pt")
    assert int(resumed.optimisation.average.n_averaged) == 0 and resumed.estimate is resumed.field
    resumed.step()
    for a, b in zip(resumed.optimisation.average.module.parameters(), resumed.field.parameters()):
        assert torch.equal(a, b)


def test_a_diverging_run_stops_and_keeps_the_last_good_checkpoint(tmp_path):
    tr = neural_solver()
    for _ in range(5):
        tr.step()
    tr.save(tmp_path / "ck.pt")
    with torch.no_grad():
        tr.field.mlp[0].weight.fill_(float("nan"))
    with pytest.raises(DivergenceError, match="diverged"):
        tr.fit(checkpoint_every=1, checkpoint=tmp_path / "ck.pt", progress=False)
    assert torch.load(tmp_path / "ck.pt", weights_only=False)["iteration"] == 5


def test_a_checkpoint_of_another_field_is_refused(tmp_path):
    tr = neural_solver("encoder=frequency")
    tr.save(tmp_path / "ck.pt")
    with pytest.raises(ValueError, match="its solver differ"):
        neural_solver("encoder=hash").load(tmp_path / "ck.pt")


def test_a_checkpoint_of_other_data_is_refused_naming_what_differs(tmp_path):
    """Issue 28: a resume onto another scene ran on and reported the old scene's figures."""
    tr = neural_solver()
    tr.step()
    tr.save(tmp_path / "checkpoint.pt")
    with pytest.raises(ValueError, match=r"another run: its observations \(RMS per view\) differ"):
        neural_solver("phantom.width_mm=9.0").load(tmp_path / "checkpoint.pt")
    with pytest.raises(ValueError, match="another run: its ambient"):
        neural_solver("phantom.T0=290").load(tmp_path / "checkpoint.pt")
    same = neural_solver()
    same.load(tmp_path)  # a run folder stands for its checkpoint.pt
    assert same.iteration == 1


def test_a_truncated_or_foreign_checkpoint_is_one_sentence(tmp_path):
    tr = neural_solver()
    tr.save(tmp_path / "ck.pt")
    data = (tmp_path / "ck.pt").read_bytes()
    (tmp_path / "cut.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="cut.pt is not a readable checkpoint"):
        neural_solver().load(tmp_path / "cut.pt")
    torch.save({"weights": torch.zeros(3)}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="other.pt is not a nerif checkpoint"):
        neural_solver().load(tmp_path / "other.pt")


def test_no_second_order_graph_when_only_the_discrete_term_trains(monkeypatch):
    calls = []
    auto = GRADIENTS.get("auto")

    def spy(field, p, *, create_graph, step_mm, across=None):
        calls.append(create_graph)
        return auto(field, p, create_graph=create_graph, step_mm=step_mm, across=across)

    monkeypatch.setitem(GRADIENTS._entries, "auto", spy)
    tr = neural_solver("grad=discrete")
    tr.step()
    assert calls == []  # training never touches autograd deflections
    tr.evaluate()
    assert calls and not any(calls)  # monitoring computes them without a graph
    calls.clear()
    neural_solver("grad=hybrid").step()
    assert calls == [True]


@pytest.mark.parametrize("override, message", [
    ("train.rays_per_batch=0", "rays per batch must be at least 1"),
    ("train.iterations=0", "iterations must be at least 1"),
    ("train.outside_fraction=1.0", "outside_fraction must be within"),
    ("sampler.samples_per_ray=1", "samples per ray K must be at least 2"),
    ("grad.weights.discrete=0", "every gradient-loss weight is zero"),
    ("encoder.log2_table_size=30", "log2_table_size must be within"),
    ("loss.ambient_faces=[w]", "ambient faces"),
    ("loss.ambient_faces=everywhere", "loss.ambient_faces must be auto or a list of faces"),
    ("loss.ambient_fallback=auto", "loss.ambient_fallback must be a list of faces"),
    ("grad.stencil=diagonal", "grad.stencil must be 'axes' or 'across'"),
    ("train.table_decay=-1", "a decay rate of at least 0"),
    ("train.ema_decay=1", "a decay within"),
    ("train.init_volume=/nonexistent/reconstruction.npz", "volume file .* does not exist"),
])
def test_settings_are_checked_before_any_data(override, message):
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        SOLVERS.build(group(tiny_config(override), "solver"))


def test_a_view_with_an_empty_2d_mask_trains_on_all_its_rays():
    cfg = tiny_config()
    scene = DATASETS.build(group(cfg, "data"))
    sl = scene.view_slice(2)
    scene.eps[sl] = 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the empty mask's warning (tests/test_backprojection.py)
        masks = MASKS.build({"name": "2d", "threshold": 1e-3, "radius_px": 2}, scene=scene)
    tr = solver(tiny_config("train.outside_fraction=0.1"), scene, masks)
    idx = tr.batches.draw(2, 16)
    assert len(idx) == 16 and bool(((idx >= sl.start) & (idx < sl.stop)).all())
    batch, sl1 = tr.batches.draw(1, 16), scene.view_slice(1)  # a view with a mask: 16 - round(1.6) = 14 rays inside it, 2 outside
    assert int(torch.isin(batch, masks.inside[1]).sum()) == 14 and bool(((batch >= sl1.start) & (batch < sl1.stop)).all())
    assert len(tr.batches.draw(0, 16)) == 16  # view 0's mask holds every ray: all 16 from inside
    assert np.isfinite(tr.step()["loss"])


@pytest.mark.parametrize("views, expected", [("all", [[5, 5, 4, 4, 4, 4]] * 2), (1, [[26, 0, 0, 0, 0, 0], [0, 26, 0, 0, 0, 0]]),
                                             (4, [[7, 7, 6, 6, 0, 0], [6, 6, 0, 0, 7, 7]])])
def test_a_batch_splits_its_rays_evenly_over_its_views_and_cycles_them(views, expected):
    tr = neural_solver(f"train.views_per_batch={views}", "train.rays_per_batch=26")
    for per_view in expected:
        views_of = torch.searchsorted(tr.scene.view_start, tr.batches(tr.iteration), right=True) - 1
        assert torch.bincount(views_of, minlength=tr.scene.n_views).tolist() == per_view
        tr.step()


@pytest.mark.slow
def test_a_small_reconstruction_cuts_the_error_well_under_half_of_the_ambient_field():
    # a 10 mm blob (peak 1200 K) in a 48 mm box, 6 views with a 2.8 mm pixel footprint, 400 iterations
    tr = neural_solver("encoder=hash", "phantom.width_mm=10.0", "rig.binning=20", "train.iterations=400",
                      "train.rays_per_batch=128")
    while tr.iteration < tr.iterations:
        tr.step()
    m = tr.evaluate()
    ambient = rmse(np.full_like(tr.scene.truth_T, tr.scene.ambient.T0), tr.scene.truth_T)
    assert m["temperature_rmse_K"] < 0.4 * ambient, (m["temperature_rmse_K"], ambient)
    assert m["deflection_rmse"] < 0.2 * float(tr.scene.eps.norm(dim=-1).pow(2).mean().sqrt())


def rendered(t, idx):
    """The discrete operator's deflections of sigma of scene rays ``idx``."""
    from nerif.solvers.data_terms import scene_rays

    batch = scene_rays(t.scene, idx)
    return t.render(batch.origins, batch.dirs, ("discrete",))["discrete"]


def test_only_the_measured_part_is_compared_when_the_scene_says_so():
    from dataclasses import replace

    t = neural_solver()
    for _ in range(5):
        t.step()
    idx = torch.arange(40)
    full = rendered(t, idx)
    d = t.scene.dirs[idx]
    assert float((full * d).sum(-1).abs().max()) > 1e-3 * float(full.norm(dim=-1).max())  # a field the box cuts
    t.scene = replace(t.scene, perpendicular_only=True)
    t.renderer.perpendicular_only = True  # as a solver set up on such a scene renders
    measured = rendered(t, idx)
    torch.testing.assert_close(measured, full - (full * d).sum(-1, keepdim=True) * d)
    t.renderer.stencil = "across"  # differences across each ray only: the same measurable part, to the stencil's O(h^2)
    across = rendered(t, idx)
    assert float((across * d).sum(-1).abs().max()) < 1e-6 * float(full.norm(dim=-1).max())
    assert float((across - measured).norm(dim=-1).max()) < 0.01 * float(measured.norm(dim=-1).max())  # 0.0025


def test_the_advice_names_the_setting_that_bounds_the_field():
    """Issue 50: a rig whose temperature_range_K bounds the field at 1000 K was told to raise data.T_max (2000 K
    already): the advice names what sets the prior, a rig file's range, field.prior or data.T_max."""
    from nerif.field import check_truth_within, hot_bound_advice, prior_interval, prior_source
    from nerif.physics import Ambient

    amb = Ambient(296.15, 1.00027, 2000.0)
    rig = "temperature_range_K [296.15, 1000.0] in cap/rig.yaml"
    prior = (float(amb.sigma_from_temperature(1000.0)) - 0.05, 0.05)  # as a capture's sigma_prior gives it
    truth = np.full((4, 4, 4), 296.15)
    truth[1, 1, 1] = 1861.0
    with pytest.raises(ValueError, match=r"set by temperature_range_K \[296.15, 1000.0\] in cap/rig.yaml\): raise the "
                                         r"upper temperature of temperature_range_K .* to 1900 K or higher \(it bounds "
                                         r"the field, not data.T_max\)"):
        check_truth_within(truth, amb, prior, prior_source(None, rig))
    assert prior_source([-0.5, 0.05], rig) == "field.prior" and prior_source(None, None) is None
    advice = hot_bound_advice(1861.0, amb, prior_interval([-0.5, 0.05]), "field.prior")
    a = float(advice.split("[")[1].split(",")[0])
    assert advice.startswith("set field.prior=[") and amb.temperature_from_sigma(np.float64(a)) >= 1900.0
    with pytest.raises(ValueError, match=r"set by data.T_max=2000 K\): set data.T_max=5800 or higher"):
        check_truth_within(truth * 3.1, amb, prior_interval(None, None))


def test_a_flame_at_the_prior_bound_is_reported_with_the_setting_to_raise():
    tr = neural_solver()
    sigma = np.zeros((10, 10, 10))
    sigma[:5] = -0.5
    assert tr.saturation(sigma) == {"flame_at_prior_bound": 0.0, "box_at_cold_bound": 0.0}
    sigma[:2] = -1.05  # 40 % of the flame pinned at the bound (data.T_max=2000 holds at most 2808 K)
    out = tr.saturation(sigma)
    assert out["flame_at_prior_bound"] == pytest.approx(0.4)
    assert len(out["warnings"]) == 1 and out["warnings"][0].startswith("40.0 % of the flame sits at the hottest 2808 K the field can hold "
                                     "(set by data.T_max=2000 K)") and "set data.T_max=2950 or higher" in out["warnings"][0]
    from nerif.field import prior_saturation  # issue 28: a diverged run blamed data.T_max, the truth far below it

    cool = np.full_like(sigma, 600.0)
    astray = prior_saturation(sigma, tr.interval, tr.scene.ambient, cool)["warnings"][0]
    assert "the known truth peaks at 600 K, far from it: the fit went astray (lower train.lr)" in astray
    failed = tr.saturation(sigma, "the fit failed: ...")["warnings"]  # issue 37: the held-out views disagree
    assert len(failed) == 1 and "raise data.T_max" not in failed[0] and "do not support a hotter flame" in failed[0]
    sigma[5:8] = 0.05  # a field pressed against the cold bound (sigma <= 0.05) over 30 % of the box
    out = tr.saturation(sigma)
    assert out["box_at_cold_bound"] == pytest.approx(0.3) and "pull the field colder than ambient" in out["warnings"][0]


def test_a_run_stops_when_its_evaluations_no_longer_improve_the_fit(tmp_path):
    """train.stop_when_converged: the best deflection RMSE on the fixed evaluation rays over the last
    stop_patience evaluations against the best before them; below the asked gain, the run ends there."""
    full = neural_solver("train.iterations=80", "train.eval_every=10")
    full.fit(checkpoint_every=1000, progress=False)
    rmse = [h["deflection_rmse"] for h in full.history]
    gains = [1 - min(rmse[k - 2:k]) / min(rmse[:k - 2]) for k in range(3, len(rmse) + 1)]  # patience 2
    tol = sorted(gains)[len(gains) // 2] + 1e-9  # the median gain: some evaluation falls short of it
    first = next(k for k, g in zip(range(3, len(rmse) + 1), gains) if g < tol)  # evaluations when it stops
    stopping = neural_solver("train.iterations=80", "train.eval_every=10", f"train.stop_when_converged={tol}",
                             "train.stop_patience=2")
    stopping.fit(checkpoint_every=1000, checkpoint=tmp_path / "ck.pt", progress=False)
    assert stopping.iteration == 10 * first < 80 and stopping.converged
    assert [h["deflection_rmse"] for h in stopping.history] == rmse[:first]  # the same run, cut short
    assert torch.load(tmp_path / "ck.pt", weights_only=False)["iteration"] == 10 * first
    with pytest.raises(ValueError, match="train.stop_when_converged=2"):
        neural_solver("train.stop_when_converged=2")


def test_the_field_tv_term_trains_only_when_weighted():
    """``loss.tv_weight`` adds the field's total variation to the loss, scaled by the RMS observed deflection of
    the rays training draws from (so that the weight is dimensionless); with weight 0 nothing is added."""
    off = neural_solver()
    assert off.tv is None and "loss_tv" not in off.step()
    on = neural_solver("loss.tv_weight=0.5")
    rms = float(on.scene.eps.norm(dim=-1).pow(2).mean().sqrt()) / on.scene.ambient.delta_thre
    assert on.tv.scale == pytest.approx(rms, rel=1e-4)  # every ray is inside: no 2-D mask here
    out = on.step()
    assert out["loss_tv"] > 0 and out["loss"] > out["loss_tv"]


@pytest.mark.parametrize("decay", [0.0, 1.0])
def test_table_decay_shrinks_only_the_hash_entries_no_ray_reaches(decay):
    """AdamW's decoupled decay: an entry without a gradient is multiplied by exactly ``1 - lr decay`` per step
    (Adam's own update is zero there); the MLP is never decayed."""
    tr = neural_solver("encoder=hash", f"train.table_decay={decay}", "train.lr=0.01")
    groups = {id(p): g["weight_decay"] for g in tr.optimisation.optimizer.param_groups for p in g["params"]}
    assert groups[id(tr.field.encoder.table)] == decay
    assert all(groups[id(p)] == 0.0 for p in tr.field.mlp.parameters())
    tr.step()  # the last layer starts at zero: no entry has a gradient yet, only the decay acts
    before, lr = tr.field.encoder.table.detach().clone(), tr.optimisation.optimizer.param_groups[0]["lr"]
    tr.step()
    untouched = (tr.field.encoder.table.grad == 0).all(dim=1)
    assert 0 < int(untouched.sum()) < len(before)
    after = tr.field.encoder.table.detach()
    torch.testing.assert_close(after[untouched], before[untouched] * (1 - lr * decay), rtol=1e-6, atol=0)
    assert not torch.allclose(after[~untouched], before[~untouched] * (1 - lr * decay))


def test_a_warm_start_begins_near_the_volume_it_is_given(tmp_path):
    """``train.init_volume``: the field is fit to a voxel volume before any ray; from the true sigma it starts at
    a few per cent of the error of the ambient (cold) start, which is 100 % by definition."""
    cold = neural_solver()
    truth = cold.scene.ambient.sigma_from_temperature(cold.scene.truth_T)
    np.savez(tmp_path / "reconstruction.npz", sigma=truth)
    assert cold.evaluate()["sigma_relative_error"] == pytest.approx(1.0)
    warm = neural_solver(f"train.init_volume={tmp_path / 'reconstruction.npz'}", "train.init_iterations=200")
    assert warm.evaluate()["sigma_relative_error"] < 0.05  # 0.008 measured
    np.savez(tmp_path / "wrong.npz", sigma=truth[:-1])
    with pytest.raises(ValueError, match="shape .* but the probe grid is"):
        neural_solver(f"train.init_volume={tmp_path / 'wrong.npz'}")
    np.save(tmp_path / "T.npy", cold.scene.truth_T)  # issue 28: a temperature file was fitted as sigma
    with pytest.raises(ValueError, match=r"T.npy holds values 296.2 to .* \(a temperature in kelvin\?\), far outside"):
        neural_solver(f"train.init_volume={tmp_path / 'T.npy'}")


@pytest.mark.parametrize("overrides, perpendicular, expected", [
    ((), False, 6), (("grad=auto",), False, 1), (("grad=hybrid",), False, 7),
    (("grad.stencil=across",), False, 6), (("grad.stencil=across",), True, 4)])
def test_the_field_evaluations_per_sample_follow_the_operators_and_the_stencil(overrides, perpendicular, expected):
    from dataclasses import replace

    tr = neural_solver(*overrides)
    tr.scene = replace(tr.scene, perpendicular_only=perpendicular)
    tr.renderer.perpendicular_only = perpendicular  # as a solver set up on such a scene renders
    assert tr.timing()["field_evaluations_per_sample"] == expected


def test_outputs_use_the_moving_average_of_the_trained_weights():
    """After n steps the reconstruction is the field whose weights are sum_k c_k w_k over the trained weights w_k of
    each step, c_k = (1 - d_k) prod_{j > k} d_j with d_k = min(decay, k / (9 + k)) and d_1 = 0 (the first step's
    weights are copied; the learning rate is still above half its peak); once the rate has annealed, the last
    weights; with ``train.ema_decay=0`` the trained field's own."""
    decay = 0.3
    tr = neural_solver(f"train.ema_decay={decay}")
    assert torch.equal(torch.as_tensor(tr.reconstruction()), torch.as_tensor(tr.field.on_grid(tr.scene.box).double()))
    iterates = []
    for _ in range(6):
        tr.step()
        iterates.append([p.detach().clone() for p in tr.field.parameters()])
    d = [0.0] + [min(decay, k / (9 + k)) for k in range(2, 7)]
    c = [(1 - d[k]) * float(np.prod(d[k + 1:])) for k in range(6)]
    assert abs(sum(c) - 1) < 1e-12 and d[1] < decay == d[5]  # both regimes
    assert tr.optimisation.rate() > 0.5  # so the window is not yet shortened by the rate
    expected = [sum(ck * w[i] for ck, w in zip(c, iterates)) for i in range(len(iterates[0]))]
    for a, e in zip(tr.optimisation.average.module.parameters(), expected):
        torch.testing.assert_close(a, e)
    with torch.no_grad():
        for p, e in zip(tr.field.parameters(), expected):
            p.copy_(e)
    np.testing.assert_allclose(tr.reconstruction(), tr.field.on_grid(tr.scene.box).double().numpy(), atol=1e-6)
    assert not torch.equal(iterates[-1][0], expected[0])  # the average is not the last weights

    ended = neural_solver("train.iterations=8")  # the rate anneals to lr_min: the average ends on the last weights
    for _ in range(8):
        ended.step()
    assert ended.optimisation.rate() < 1e-3
    for a, b in zip(ended.optimisation.average.module.parameters(), ended.field.parameters()):
        assert torch.equal(a, b)

    last = neural_solver("train.ema_decay=0")
    last.step()
    assert last.optimisation.average is None
    np.testing.assert_array_equal(last.reconstruction(), last.field.on_grid(last.scene.box).double().numpy())


def test_clones_are_new_solvers_from_the_trained_state_each_independent_of_the_others():
    """Issue 57: a clone (an ensemble's member) is a new solver made from the trained one, which it leaves as it was;
    a clone's field depends on its own views, seed and rate alone, not on clones trained before it (each started
    from the field the member before it left, when members were the running solver changed in place)."""
    s = neural_solver("train.iterations=8")
    for _ in range(8):
        s.step()
    before = {k: v.clone() for k, v in s.estimate.state_dict().items()}
    first = s.clone([0, 1, 2], 3, iterations=4, lr_factor=0.3, perturb=0.5)
    assert first is not s and first.iteration == 8 and first.iterations == 12
    assert first.train() and first.iteration == 12 and s.iteration == 8
    other = s.clone([1, 2, 3], 4, iterations=4, lr_factor=0.3, perturb=0.5)
    assert other.train()
    again = s.clone([0, 1, 2], 3, iterations=4, lr_factor=0.3, perturb=0.5)
    assert again.train()
    np.testing.assert_array_equal(again.reconstruction(), first.reconstruction())
    assert not np.array_equal(other.reconstruction(), first.reconstruction())
    for k, v in s.estimate.state_dict().items():
        torch.testing.assert_close(v, before[k], rtol=0, atol=0)
    assert first.optimisation.optimizer.param_groups[0]["lr"] < 0.3 * 5e-3  # its own cosine, down from 0.3 of the peak
