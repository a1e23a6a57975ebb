import numpy as np
import pytest
import scipy.sparse.linalg as sla
import torch

from nerif.geometry import ProbeBox, arc_rig, rays_in_box
from nerif.registry import UnknownComponent
from nerif.solvers.voxel.cgls import CGLS, forward_differences, laplacian
from nerif.solvers.voxel.projector import SparseProjector


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
    with pytest.raises(UnknownComponent, match="unknown regularizer 'l1'"):
        CGLS(P.Ax, P.Atb, torch.as_tensor(b).reshape(-1, 3), box.shape, regularizer="l1", lam=1.0)
    with pytest.raises(ValueError, match="needs a weight lam > 0"):
        CGLS(P.Ax, P.Atb, torch.as_tensor(b).reshape(-1, 3), box.shape, regularizer="tv")
