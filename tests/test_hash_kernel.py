"""The fused hash-encoding kernels against the tensor reference: values and table gradients to float tolerance.

Both backends run here: ``cpp`` compiled for this CPU, ``triton`` in Triton's interpreter (``TRITON_INTERPRET=1``,
set in conftest.py: the same kernel source as on a GPU, executed block by block with NumPy)."""
import pytest
import torch

from nerif.encoders import hash_kernel
from nerif.encoders import hash as hash_module
from nerif.encoders.hash import HashGrid

BACKENDS = [pytest.param(b, marks=pytest.mark.skipif(not hash_kernel.available(b), reason=f"{b} cannot run here"))
            for b in hash_kernel.BACKENDS]
CASES = [  # dense levels only; dense + hashed (2^10 entries, resolutions to 64); the paper's table and resolutions
    dict(n_levels=2, log2_table_size=15, base_resolution=4, max_resolution=16),
    dict(n_levels=4, log2_table_size=10, base_resolution=16, max_resolution=64),
    dict(n_levels=3, log2_table_size=19, base_resolution=16, max_resolution=512),
]


def encoders(case: dict, interpolation: str, backend: str, n_features: int = 2):
    ref = HashGrid(**case, n_features=n_features, init_scale=1.0, interpolation=interpolation, kernel="torch")
    fused = HashGrid(**case, n_features=n_features, init_scale=1.0, interpolation=interpolation, kernel=backend)
    fused.load_state_dict(ref.state_dict())
    return ref, fused


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("interpolation", ["linear", "smoothstep"])
@pytest.mark.parametrize("case", CASES)
def test_fused_matches_reference(case, interpolation, backend):
    ref, fused = encoders(case, interpolation, backend)
    n = hash_kernel.BLOCK + 88  # two blocks, the second part-filled; some points beyond [-1, 1] (clamped)
    x = torch.rand(n, 3) * 2.4 - 1.2
    x[:4] = torch.tensor([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [1.0, -1.0, 0.0], [0.0, 0.0, 0.0]])  # faces, corners
    assert fused.backend(x) == backend and ref.backend(x) is None
    y_ref, y = ref(x), fused(x)
    assert y.shape == y_ref.shape == (n, ref.out_dim)
    assert torch.allclose(y, y_ref, rtol=1e-5, atol=1e-6)
    g = torch.randn_like(y)
    (grad_ref,) = torch.autograd.grad(y_ref, ref.table, g)
    (grad,) = torch.autograd.grad(y, fused.table, g)
    assert grad.abs().max() > 0.1  # the check below compares real gradients
    assert torch.allclose(grad, grad_ref, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("n_features", [1, 3, 4])  # the cpp kernel: compiled for 1, 2 and 4, any other count (3)
def test_other_feature_counts_and_no_points(backend, n_features):
    ref, fused = encoders(CASES[1], "linear", backend, n_features=n_features)
    x = torch.rand(50, 3) * 2 - 1
    y = fused(x)
    assert torch.allclose(y, ref(x), rtol=1e-5, atol=1e-6)
    g = torch.randn_like(y)
    (grad_ref,) = torch.autograd.grad(ref(x), ref.table, g)
    (grad,) = torch.autograd.grad(y, fused.table, g)
    assert torch.allclose(grad, grad_ref, rtol=1e-5, atol=1e-6)
    empty = fused(torch.zeros(0, 3))
    assert empty.shape == (0, ref.out_dim)
    empty.sum().backward()
    assert fused.table.grad.abs().sum() == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_positions_that_need_a_gradient_take_the_reference(backend):
    """grad=auto differentiates the encoding by position: the kernels give no position gradient, so the encoder
    must not use them there (the position gradient then equals the reference's)."""
    ref, fused = encoders(CASES[1], "smoothstep", backend)
    x = (torch.rand(40, 3) * 2 - 1).requires_grad_(True)
    assert fused.backend(x) is None
    (gx_ref,) = torch.autograd.grad(ref(x).sum(), x)
    (gx,) = torch.autograd.grad(fused(x).sum(), x)
    assert gx.abs().max() > 0 and torch.allclose(gx, gx_ref)


@pytest.mark.parametrize("backend", BACKENDS)
def test_training_steps_match(backend):
    """Three training steps of the tiny scene's solver (discrete gradients, 3-D gate, ambient boundary) with the
    kernels and with the reference: the same losses and table gradients, to float tolerance."""
    from nerif.configs import group
    from nerif.data import DATASETS
    from nerif.masks import MASKS
    from tests.helpers import solver, tiny_config

    runs = []
    for kernel in ("torch", backend):
        cfg = tiny_config("encoder.kernel=" + kernel, "mask=3d", "sampler=uniform", "field.hash_levels=2",
                          "train.rays_per_batch=8", "sampler.samples_per_ray=8")
        scene = DATASETS.build(group(cfg, "data"))
        torch.manual_seed(0)
        s = solver(cfg, scene, MASKS.build(group(cfg, "mask"), scene=scene))
        losses = []
        for i in range(3):
            losses.append(s.step()["loss"])
            s.iteration += 1
            if i == 1:  # a table gradient (step 0 has none: the last layer starts at zero; later Adam steps amplify rounding)
                grad = s.field.encoder.table.grad.clone()
        runs.append((losses, grad))
    (l_ref, g_ref), (l, g) = runs
    assert l_ref[-1] < l_ref[0]  # the steps train
    assert l == pytest.approx(l_ref, rel=1e-4)
    assert g_ref.abs().max() > 0 and (g_ref - g).abs().max() <= 1e-4 * g_ref.abs().max()


def test_auto_takes_the_cpu_kernel_here_when_it_builds():
    enc = HashGrid(n_levels=2, max_resolution=32, kernel="auto")
    x = torch.rand(5, 3)
    assert enc.backend(x) == ("cpp" if hash_module.kernels_agree("cpp", x.device) else None)
    assert enc.backend(x.requires_grad_(True)) is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernels_that_fail_leave_the_tensor_path(monkeypatch, caplog, backend):
    """kernel=auto on a device where the kernels fail (a compiler that cannot build them) warns once and encodes
    through the tensor path: the run goes on, slower."""

    def broken(*args):
        raise RuntimeError("the kernel's compilation failed")

    monkeypatch.setattr(hash_kernel.FusedHashEncoding, "apply", broken)
    hash_module.kernels_agree.cache_clear()
    try:
        assert not hash_module.kernels_agree(backend, torch.device("cpu"))
        assert "the kernel's compilation failed" in caplog.text and "tensor path" in caplog.text
        assert HashGrid(n_levels=2, max_resolution=32, kernel="auto").backend(torch.rand(3, 3)) is None
    finally:
        hash_module.kernels_agree.cache_clear()


@pytest.mark.parametrize("backend", BACKENDS)
def test_kernels_agree_with_the_reference_here(backend):
    hash_module.kernels_agree.cache_clear()
    with torch.no_grad():  # as from an evaluation: the check still differentiates
        assert hash_module.kernels_agree(backend, torch.device("cpu"))
    hash_module.kernels_agree.cache_clear()


def test_a_double_table_takes_the_tensor_path():
    ref = HashGrid(n_levels=2, max_resolution=32, kernel="torch").double()
    enc = HashGrid(n_levels=2, max_resolution=32, kernel="cpp" if hash_kernel.available("cpp") else "auto").double()
    enc.load_state_dict(ref.state_dict())
    x = torch.rand(20, 3, dtype=torch.float64) * 2 - 1
    assert enc.backend(x) is None
    assert enc(x).dtype == torch.float64 and torch.equal(enc(x), ref(x))


def test_an_unknown_kernel_is_refused():
    with pytest.raises(ValueError, match="hash kernel must be auto, torch, triton or cpp"):
        HashGrid(kernel="cuda")


def test_each_python_environment_keeps_its_own_kernel_build(monkeypatch, tmp_path):
    """Issue 35: two environments on one machine rebuilt each other's kernel in torch's shared extension folder."""
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path))
    monkeypatch.setattr("sys.prefix", "/envs/a")
    a = hash_kernel.build_directory()
    monkeypatch.setattr("sys.prefix", "/envs/b")
    b = hash_kernel.build_directory()
    assert a != b and a.parent == b.parent == tmp_path and a.is_dir() and b.is_dir()
    monkeypatch.setattr("sys.prefix", "/envs/a")
    assert hash_kernel.build_directory() == a  # the same environment finds its own build again
