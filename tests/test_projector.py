import pytest
import torch

from nerif.solvers.voxel.projector import PROJECTORS
from nerif.geometry import rays_in_box
from nerif.geometry import ProbeBox, arc_rig
from nerif.renderers.voxel import voxel_deflection


def _rays(box, n_cameras=6, binning=40, dtype=torch.float64):
    o, d, _, vs = rays_in_box(box, arc_rig(n_cameras=n_cameras, binning=binning))
    return o[torch.repeat_interleave(torch.arange(n_cameras), vs.diff())].to(dtype), d.to(dtype)


@pytest.mark.parametrize("name", ["matrix_free", "sparse"])
@pytest.mark.parametrize("dtype, tol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_adjoint_identity(name, dtype, tol):
    box = ProbeBox((12, 16, 10), 2.5)
    o, d = _rays(box, dtype=dtype)
    A = PROJECTORS.build({"name": name}, box=box, origins=o, dirs=d, chunk=300)
    g = torch.Generator().manual_seed(0)
    x = torch.randn(box.shape, generator=g, dtype=dtype)
    y = torch.randn(len(d), 3, generator=g, dtype=dtype)
    lhs, rhs = float((A.Ax(x) * y).sum()), float((x * A.Atb(y)).sum())
    assert abs(lhs - rhs) <= tol * abs(lhs)


def test_both_projectors_are_the_voxel_forward_model():
    box = ProbeBox((12, 16, 10), 2.5)
    o, d = _rays(box)
    x = torch.randn(box.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    ref = voxel_deflection(x, box, o, d)
    for name in ("matrix_free", "sparse"):
        A = PROJECTORS.build({"name": name}, box=box, origins=o, dirs=d, chunk=250)
        torch.testing.assert_close(A.Ax(x), ref, rtol=1e-10, atol=1e-12)


def test_the_sparse_matrix_is_stored_with_32_bit_indices_and_its_size_is_estimated_from_a_few_rays():
    """The estimate from 200 rays is within 10 % of what S and its transpose take once built (int32 indices);
    the old bound (every sample's 8 corners, int64) was 5-13x too large and sent large cases to the slow
    matrix-free projector."""
    from nerif.solvers.voxel.projector import SparseProjector

    box = ProbeBox((12, 16, 10), 2.5)
    o, d = _rays(box, binning=20, dtype=torch.float32)
    P = SparseProjector(box, o, d, chunk=500)
    assert P.S.col_indices().dtype == torch.int32 and P.St.crow_indices().dtype == torch.int32
    stored = sum(t.numel() * t.element_size() for M in (P.S, P.St)
                 for t in (M.crow_indices(), M.col_indices(), M.values()))
    estimate = SparseProjector.memory_bytes(box, o, d, probe_rays=200)
    assert abs(estimate - stored) < 0.1 * stored, (estimate, stored)
    dense = P.S.to_dense()
    assert torch.equal(P.St.to_dense(), dense.T)
