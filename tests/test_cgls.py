from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse.linalg as sla
import torch

from nerif.baselines.cgls import CGLS, forward_differences, laplacian
from nerif.baselines.projector import SparseProjector
from nerif.baselines.solver import CGLSSolver, boundary_mask
from nerif.data import DATASETS
from nerif.data.scene import rays_in_box
from nerif.geometry import ProbeBox, arc_rig


def _small_problem():
    box = ProbeBox((6, 7, 5), 3.0)
    o, d, _, vs = rays_in_box(box, arc_rig(n_cameras=8, binning=80))
    o = o[torch.repeat_interleave(torch.arange(8), vs.diff())].double()
    P = SparseProjector(box, o, d.double())
    n = int(np.prod(box.shape))
    A = torch.stack([P.Ax(e.reshape(box.shape)).flatten() for e in torch.eye(n, dtype=torch.float64)], 1).numpy()
    b = A @ np.random.default_rng(0).standard_normal(n) + 1e-3 * np.random.default_rng(1).standard_normal(A.shape[0])
    return box, P, A, b


def _run(c: CGLS, iterations: int) -> np.ndarray:
    for _ in range(iterations):
        c.step()
    return c.solution().flatten().numpy()


def test_cgls_reaches_the_least_squares_solutions_of_scipy_lsqr():
    box, P, A, b = _small_problem()
    bt = torch.as_tensor(b).reshape(-1, 3)
    # Tikhonov: a well-posed problem, one solution
    lam = 1e-3
    ref = sla.lsqr(A, b, damp=lam**0.5, atol=1e-15, btol=1e-15, iter_lim=50000)[0]
    x = _run(CGLS(P.Ax, P.Atb, bt, box.shape, regularizer="tikhonov", lam=lam), 400)
    assert np.linalg.norm(x - ref) <= 1e-4 * np.linalg.norm(ref)
    # plain: the minimum-norm least-squares solution (both start from zero; A has a null space: constants)
    ref = sla.lsqr(A, b, atol=1e-15, btol=1e-15, iter_lim=50000)[0]
    x = _run(CGLS(P.Ax, P.Atb, bt, box.shape), 400)
    assert np.linalg.norm(x - ref) <= 1e-4 * np.linalg.norm(ref)


def test_mask_restricts_the_unknowns_and_regularizers_are_linear_and_named():
    box, P, A, b = _small_problem()
    mask = torch.zeros(box.shape, dtype=torch.float64)
    mask[1:-1, 1:-1, 1:-1] = 1
    x = _run(CGLS(P.Ax, P.Atb, torch.as_tensor(b).reshape(-1, 3), box.shape, mask=mask), 20).reshape(box.shape)
    assert np.all(x[mask.numpy() == 0] == 0) and np.abs(x).max() > 0
    v = torch.randn(box.shape, dtype=torch.float64)
    torch.testing.assert_close(laplacian(2 * v), 2 * laplacian(v))
    assert float(forward_differences(torch.ones(box.shape)).abs().max()) == 0
    with pytest.raises(KeyError, match="unknown regularizer 'l1'"):
        CGLS(P.Ax, P.Atb, torch.as_tensor(b).reshape(-1, 3), box.shape, regularizer="l1", lam=1.0)
    with pytest.raises(ValueError, match="needs a weight lam > 0"):
        CGLS(P.Ax, P.Atb, torch.as_tensor(b).reshape(-1, 3), box.shape, regularizer="tv")
    assert boundary_mask((4, 5, 6), ["x"]).sum() == 2 * 5 * 6


def test_cgls_reconstructs_a_gaussian_blob_from_twelve_views():
    sc = DATASETS.build({"name": "synthetic", "rig": {"n_cameras": 12, "binning": 20}, "T_max": 2000.0,
                         "phantom": {"name": "gaussian_blob", "shape": [24, 24, 24], "voxel_mm": 2.0, "width_mm": 6.0},
                         "render_supersample": 2})
    s = CGLSSolver(sc, iterations=60)
    for _ in range(60):
        s.step()
    m = s.evaluate()
    assert m["temperature_rmse_K"] < 10.0, m  # peak 1200 K over 296 K ambient
    assert m["relative_residual"] < 0.1
    # predictions of any rays (held-out views) are the forward model of the solution: on the training rays,
    # the observations minus the CGLS residual
    pred = s.predict(sc.origins[sc.ray_views()], sc.dirs)
    assert torch.allclose(pred, sc.eps - s.cgls.r * s.scale, atol=1e-3 * float(sc.eps.abs().max()))


def test_total_variation_beats_plain_cgls_on_a_hot_cube_under_noise(tmp_path):
    T = np.full((20, 20, 20), 296.15)
    c = (np.indices(T.shape) - 9.5) * 2.0
    T[(np.abs(c) < 8).all(0)] = 900.0
    np.save(tmp_path / "cube.npy", T)
    sc = DATASETS.build({"name": "synthetic", "rig": {"n_cameras": 12, "binning": 20}, "T_max": 2000.0,
                         "phantom": {"name": "file", "path": str(tmp_path / "cube.npy"), "voxel_mm": 2.0,
                                     "T0": 296.15, "n0": 1.00027}})
    noise = torch.randn(sc.eps.shape, generator=torch.Generator().manual_seed(0), dtype=sc.eps.dtype)
    sc = replace(sc, eps=sc.eps + 0.02 * float(sc.eps.abs().max()) * noise)

    def sigma_rmse(regularizer, lam, iterations):
        s = CGLSSolver(sc, iterations=iterations, regularizer=regularizer, lam=lam, dtype="float64")
        for _ in range(iterations):
            s.step()
        return s.evaluate()["sigma_rmse"]

    best_plain = min(sigma_rmse("none", 0.0, k) for k in (5, 10, 20, 40))  # plain CGLS stopped at its best
    assert sigma_rmse("tv", 1e-2, 60) < 0.6 * best_plain


def test_discrepancy_stops_early_and_the_run_is_resumable(tmp_path):
    sc = DATASETS.build({"name": "synthetic", "rig": {"n_cameras": 6, "binning": 40}, "T_max": 2000.0,
                         "phantom": {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 3.0, "width_mm": 7.0}})
    s = CGLSSolver(sc, iterations=500, tol=0.05)
    last = s.fit(eval_every=5, checkpoint_every=5, checkpoint=tmp_path / "ck.pt", progress=False)
    assert s.iteration < 500 and last["relative_residual"] < 0.05
    again = CGLSSolver(sc, iterations=s.iteration + 3)
    again.load(tmp_path / "ck.pt")
    plain = CGLSSolver(sc, iterations=s.iteration + 3)
    for _ in range(s.iteration + 3):
        plain.step()
    for _ in range(3):
        again.step()
    np.testing.assert_allclose(again.reconstruction(), plain.reconstruction(), rtol=1e-5, atol=1e-7)
