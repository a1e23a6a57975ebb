"""The multiresolution hash encoding: levels, dense and hashed indexing, derivatives, the table's gather."""
import torch

from nerif.encoders.hash import HashGrid, _Gather


def test_hash_levels_follow_the_paper_and_dense_levels_are_exact():
    enc = HashGrid(n_levels=16, log2_table_size=19, max_resolution=512)  # the paper's
    assert enc.out_dim == 32 and enc.resolutions[0] == 16 and enc.resolutions[-1] == 512
    # a coarse (dense) level interpolates its grid values exactly at the grid points
    enc = HashGrid(n_levels=1, base_resolution=4, max_resolution=4, log2_table_size=10, interpolation="linear")
    with torch.no_grad():
        enc.table.copy_(torch.arange(enc.table.numel(), dtype=torch.float32).reshape(-1, 2))
    # grid point (1, 2, 3) of 4 cells per axis: u = (1, 2, 3) / 4, stride 8 -> row 1 + 8 * 2 + 64 * 3
    u = torch.tensor([[1, 2, 3]]) / 4.0
    torch.testing.assert_close(enc(u * 2 - 1), enc.table[1 + 16 + 192][None].detach())


def test_hash_index_matches_instant_ngp_spatial_hash():
    enc = HashGrid(n_levels=1, base_resolution=200, max_resolution=200, log2_table_size=12, interpolation="linear")
    with torch.no_grad():
        enc.table.copy_(torch.randn_like(enc.table))
    corner = (37, 150, 9)
    h = (corner[0] * 1 ^ corner[1] * 2654435761 ^ corner[2] * 805459861) % 2**12  # int64 reference
    x = torch.tensor([corner], dtype=torch.float32) / 200 * 2 - 1
    torch.testing.assert_close(enc(x), enc.table[h][None].detach())


def test_smoothstep_hash_has_second_derivatives_that_train_its_table():
    enc = HashGrid(n_levels=4, base_resolution=4, max_resolution=32, log2_table_size=12, interpolation="smoothstep")
    with torch.no_grad():
        enc.table.uniform_(-1, 1)
    x = (torch.rand(64, 3) * 1.6 - 0.8).requires_grad_(True)
    y = enc(x).sum()
    (g,) = torch.autograd.grad(y, x, create_graph=True)
    (h,) = torch.autograd.grad(g[:, 0].sum(), x, create_graph=True)
    assert h[:, 0].abs().mean() > 1e-3  # d2/dx2 non-zero inside cells
    enc.table.grad = None
    (g ** 2).sum().backward()  # a loss on the spatial gradient reaches the table
    assert enc.table.grad is not None and enc.table.grad.abs().sum() > 0


def test_linear_hash_has_no_second_derivative_along_an_axis():
    enc = HashGrid(n_levels=2, base_resolution=4, max_resolution=8, log2_table_size=12, interpolation="linear")
    with torch.no_grad():
        enc.table.uniform_(-1, 1)
    x = (torch.rand(32, 3) * 1.6 - 0.8).requires_grad_(True)
    (g,) = torch.autograd.grad(enc(x).sum(), x, create_graph=True)
    (h,) = torch.autograd.grad(g[:, 0].sum(), x, allow_unused=True)
    assert h is None or h[:, 0].abs().max() < 1e-5


def test_table_gather_gradients_pass_gradcheck_twice():
    table = torch.randn(9, 2, dtype=torch.float64, requires_grad=True)
    index = torch.tensor([0, 3, 3, 8, 1, 3])
    assert torch.autograd.gradcheck(lambda t: _Gather.apply(t, index), (table,))
    assert torch.autograd.gradgradcheck(lambda t: _Gather.apply(t, index), (table,))


def test_a_ramp_is_exact_with_trilinear_weights_and_a_staircase_with_smoothstep():
    """One dense level whose node values are a ramp in x: trilinear weights give the ramp everywhere (slope 1);
    smoothstep weights are flat at every node, so the slope there is 0 and 1.5 mid-cell (why the default is
    trilinear: a staircase at each level's cell size is structure the few views of a BOS rig cannot cancel)."""
    r = 8
    x = torch.linspace(-0.95, 0.95, 101)
    p = torch.stack([x, torch.zeros_like(x), torch.zeros_like(x)], -1).requires_grad_(True)
    slopes = {}
    for interp in ("linear", "smoothstep"):
        enc = HashGrid(n_levels=1, n_features=1, base_resolution=r, max_resolution=r, log2_table_size=12,
                       interpolation=interp)
        stride = int(enc.mult[0, 1])
        idx = torch.arange(enc.table.shape[0])
        with torch.no_grad():
            enc.table[:, 0] = (idx % stride).float() / r  # node value = node x in [0, 1]: a ramp of slope 1 / 2
        (g,) = torch.autograd.grad(enc(p).sum(), p)
        slopes[interp] = g[:, 0] * 2  # per unit of u = (x + 1) / 2
    torch.testing.assert_close(slopes["linear"], torch.ones(101), atol=1e-4, rtol=0)
    u = (x + 1) / 2 * r
    t = u - u.floor()
    torch.testing.assert_close(slopes["smoothstep"], 6 * t * (1 - t), atol=1e-3, rtol=0)
    assert float(slopes["smoothstep"].min()) < 0.1 and float(slopes["smoothstep"].max()) > 1.4
