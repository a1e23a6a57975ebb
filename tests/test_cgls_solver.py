"""The voxel CGLS solver on scenes: accuracy, regularisation, early stop and resume, its settings checked."""
from dataclasses import replace

import numpy as np
import pytest
import torch

from nerif.data import DATASETS
from nerif.solvers.voxel.solver import boundary_mask
from tests.helpers import solver, tiny_config


def cgls(scene, *overrides):
    return solver(tiny_config("solver=cgls", *overrides), scene)


def test_boundary_mask_frees_all_but_the_ambient_faces():
    assert boundary_mask((4, 5, 6), ["x"]).sum() == 2 * 5 * 6
    assert boundary_mask((4, 5, 6), ["x", "z"]).sum() == 2 * 5 * 4


@pytest.mark.parametrize("overrides, error, message", [
    (["solver.regularizer=tv", "solver.lam=0"], ValueError, "needs a weight solver.lam > 0"),
    (["solver.regularizer=l1"], ValueError, "unknown regularizer 'l1'"),
    (["solver.projector=dense"], ValueError, "unknown projector 'dense'"),
    (["solver.dtype=float16"], ValueError, "float32 or float64"),
    (["loss.ambient_faces=[w]"], ValueError, "ambient faces"),
    # issue 36: these were silently ignored
    (["data_term.patch=4"], ValueError, r"^data_term.patch=4: solver=cgls does not use it \(the neural"),
    (["data_term=images", "data_term.flow_weight=0", "data_term.interpolation=bilinear"], ValueError,
     "data_term.interpolation=bilinear, data_term.flow_weight=0: solver=cgls does not use them"),
])
def test_settings_are_checked_before_any_data(overrides, error, message):
    from nerif.configs import group
    from nerif.solvers import SOLVERS

    with pytest.raises(error, match=message):
        SOLVERS.build(group(tiny_config("solver=cgls", *overrides), "solver"))


def test_the_seed_picks_the_held_out_rays_followed_during_the_run():
    sc = DATASETS.build({"name": "synthetic", "render_supersample": 1, "rig": {"name": "arc", "n_cameras": 6, "binning": 40}, "T_max": 2000.0,
                         "phantom": {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 3.0, "width_mm": 7.0}})
    sc = sc.split_views([5])
    a, b, c = (cgls(sc, f"seed={k}", "metrics.eval_rays_per_view=8") for k in (0, 0, 1))
    assert torch.equal(a.evaluation.heldout_index, b.evaluation.heldout_index) and not torch.equal(a.evaluation.heldout_index, c.evaluation.heldout_index)
    assert len(a.evaluation.heldout_index) == 8


def test_cgls_reconstructs_a_gaussian_blob_from_twelve_views():
    sc = DATASETS.build({"name": "synthetic", "rig": {"name": "arc", "n_cameras": 12, "binning": 20}, "T_max": 2000.0,
                         "phantom": {"name": "gaussian_blob", "shape": [24, 24, 24], "voxel_mm": 2.0, "width_mm": 6.0},
                         "render_supersample": 2})
    s = cgls(sc, "solver.iterations=60")
    for _ in range(60):
        s.step()
    m = s.evaluate()
    assert m["temperature_rmse_K"] < 10.0, m  # peak 1200 K over 296 K ambient
    assert m["relative_residual"] < 0.1
    # predictions of any rays (held-out views, sigma units) are the forward model of the solution: on the training rays,
    # the observations minus the CGLS residual
    pred = s.predict(sc.origins[sc.ray_views()], sc.dirs)
    assert torch.allclose(pred, sc.observed - s.cgls.r, atol=1e-3 * float(sc.observed.abs().max()))


def test_total_variation_beats_plain_cgls_on_a_hot_cube_under_noise(tmp_path):
    T = np.full((20, 20, 20), 296.15)
    c = (np.indices(T.shape) - 9.5) * 2.0
    T[(np.abs(c) < 8).all(0)] = 900.0
    np.save(tmp_path / "cube.npy", T)
    sc = DATASETS.build({"name": "synthetic", "render_supersample": 1, "rig": {"name": "arc", "n_cameras": 12, "binning": 20}, "T_max": 2000.0,
                         "phantom": {"name": "file", "path": str(tmp_path / "cube.npy"), "voxel_mm": 2.0,
                                     "T0": 296.15, "n0": 1.00027}})
    noise = torch.randn(sc.eps.shape, generator=torch.Generator().manual_seed(0), dtype=sc.eps.dtype)
    sc = replace(sc, eps=sc.eps + 0.02 * float(sc.eps.abs().max()) * noise)

    def sigma_rmse(regularizer, lam, iterations):
        s = cgls(sc, f"solver.iterations={iterations}", f"solver.regularizer={regularizer}", f"solver.lam={lam}",
                 "solver.dtype=float64")
        for _ in range(iterations):
            s.step()
        return s.evaluate()["sigma_rmse"]

    best_plain = min(sigma_rmse("none", 0.0, k) for k in (5, 10, 20, 40))  # plain CGLS stopped at its best
    assert sigma_rmse("tv", 1e-2, 60) < 0.6 * best_plain


def test_discrepancy_stops_early_and_the_run_is_resumable(tmp_path):
    sc = DATASETS.build({"name": "synthetic", "render_supersample": 1, "rig": {"name": "arc", "n_cameras": 6, "binning": 40}, "T_max": 2000.0,
                         "phantom": {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 3.0, "width_mm": 7.0}})
    s = cgls(sc, "solver.iterations=500", "solver.tol=0.05", "solver.eval_every=5")
    last = s.fit(checkpoint_every=5, checkpoint=tmp_path / "ck.pt", progress=False)
    assert s.iteration < 500 and last["relative_residual"] < 0.05
    again = cgls(sc, f"solver.iterations={s.iteration + 3}")
    again.load(tmp_path / "ck.pt")
    plain = cgls(sc, f"solver.iterations={s.iteration + 3}")
    for _ in range(s.iteration + 3):
        plain.step()
    for _ in range(3):
        again.step()
    np.testing.assert_allclose(again.reconstruction(), plain.reconstruction(), rtol=1e-5, atol=1e-7)


def test_views_weighed_by_their_noise_reconstruct_better_than_alike():
    """Issue 47: CGLS accepted ``data_term.noise_weighted`` and weighed every view alike. Two of eight views with 4x
    the deflection noise, their images' noise read 4x too: weighed (their rows by 1/4), the blob comes out closer to
    its truth than with every view alike; a setting CGLS does not read is refused."""
    sc = DATASETS.build({"name": "synthetic", "render_supersample": 1, "rig": {"name": "arc", "n_cameras": 8, "binning": 20},
                         "T_max": 2000.0, "phantom": {"name": "gaussian_blob", "shape": [20, 20, 20], "voxel_mm": 2.5,
                                                      "width_mm": 6.0}})
    noisy_views = (2, 5)
    level = torch.ones(sc.n_views, dtype=sc.eps.dtype)
    level[list(noisy_views)] = 4.0
    noise = torch.randn(sc.eps.shape, generator=torch.Generator().manual_seed(0), dtype=sc.eps.dtype)
    rms = float(sc.eps.norm(dim=-1).pow(2).mean().sqrt())
    sc = replace(sc, eps=sc.eps + 0.1 * rms * level[sc.ray_views()][:, None] * noise).with_found(
        noise=[0.01 * float(x) for x in level])

    def error(weighted):
        s = cgls(sc, "data_term=flow", f"data_term.noise_weighted={weighted}", "solver.iterations=30",
                 "solver.regularizer=tv", "solver.lam=0.01")
        for _ in range(30):
            s.step()
        return s.evaluate()["sigma_relative_error"]

    weighted, alike = error(True), error(False)
    assert weighted < 0.9 * alike, (weighted, alike)
    from nerif.configs import group
    from nerif.solvers import SOLVERS

    with pytest.raises(ValueError, match="data_term.shake_lr=0.001, data_term.pixels_per_cell=64: solver=cgls does not"):
        SOLVERS.build(group(tiny_config("solver=cgls", "data_term.shake_lr=1e-3", "data_term.pixels_per_cell=64"),
                            "solver"))
