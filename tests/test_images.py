"""The image data term's blocks against independent truths: an analytic background texture shifted by known
displacements, finite differences, exact bilinear interpolation of linear fields."""
import math

import pytest
import torch

from nerif.losses.images import bandpass, cell_origin, cell_weights, photometric_residual, photometric_scale
from nerif.sensing.interpolation import Bicubic, interpolation

BICUBIC = Bicubic()

H, W = 64, 80


WAVES = [(4.1, 0.3, 0.9), (5.3, 1.9, 2.1), (6.2, 2.8, 0.2), (7.4, 0.9, 1.3), (8.9, 2.2, 2.9), (4.7, 1.4, 0.6)]


def texture(x, y):
    """A band-limited background (plane waves of wavelengths 4-9 px in six directions), evaluated exactly
    anywhere, as a speckle background an independent program renders."""
    return 0.5 + sum(0.06 * torch.cos(2 * math.pi * (x * math.cos(a) + y * math.sin(a)) / lam + ph)
                     for lam, a, ph in WAVES)


def shifted_pair(noise: float = 0.01, seed: int = 0, gain=None):
    """Reference and distorted image of :func:`texture` (the distorted one shows it at x + u), each with its own
    Gaussian noise; ``gain``: a smooth brightness change (H, W) multiplying the distorted one. Returns the images,
    the interior pixels (P, 2) and their true displacements (P, 2)."""
    rows, cols = torch.meshgrid(torch.arange(H, dtype=torch.float64), torch.arange(W, dtype=torch.float64),
                                indexing="ij")
    u = torch.stack([0.8 * torch.sin(cols / 15), 0.5 * torch.cos(rows / 11)], -1)
    g = torch.Generator().manual_seed(seed)
    ref = texture(cols, rows) + noise * torch.randn(H, W, generator=g, dtype=torch.float64)
    dist = texture(cols + u[..., 0], rows + u[..., 1])
    if gain is not None:
        dist = dist * gain(cols, rows)
    dist = dist + noise * torch.randn(H, W, generator=g, dtype=torch.float64)
    inner = (slice(12, -12), slice(12, -12))
    return ref, dist, torch.stack([cols, rows], -1)[inner].reshape(-1, 2), u[inner].reshape(-1, 2)


def rms(r):
    return float(r.pow(2).mean().sqrt())


@pytest.mark.parametrize("name", ["bicubic", "bspline", "bandlimited"])
def test_the_residual_at_the_true_displacements_is_the_noise_and_far_above_it_0_3_px_off(name):
    noise = 0.01
    ref, dist, x, u = shifted_pair(noise)
    read = interpolation(name)
    grid = read.grid(ref)
    floor = math.sqrt(2) * noise  # two independent noisy images
    assert rms(photometric_residual(grid, dist, x, u, read)) < 1.05 * floor
    for off in ([0.3, 0.0], [0.0, -0.3], [0.21, 0.21]):
        assert rms(photometric_residual(grid, dist, x, u + torch.tensor(off, dtype=u.dtype), read)) > 1.8 * floor


@pytest.mark.parametrize("name", ["bicubic", "bilinear", "bspline", "bandlimited"])
def test_the_residuals_gradient_in_the_displacements_is_the_finite_differences(name):
    ref, dist, x, u = shifted_pair()
    read = interpolation(name)
    grid = read.grid(ref)
    u = (u[:40] + 0.137).clone().requires_grad_(True)  # off the pixel grid, where bilinear is smooth too
    assert torch.autograd.gradcheck(lambda v: photometric_residual(grid, dist, x[:40], v, read), (u,), eps=1e-6,
                                    atol=1e-5)


@pytest.mark.parametrize("name", ["bicubic", "bandlimited"])
def test_the_scale_turns_the_mean_squared_residual_into_the_squared_displacement_error(name):
    """A displacement error du, averaged over its direction and sign (which cancels the interpolation's own error
    against the texture's gradient), adds |grad I|^2 / 2 |du|^2 to the mean squared residual: with unit gain (A =
    the identity's first two rows, |A|_F^2 / 2 = 1), that excess over the scale gives |du|^2 back."""
    ref, dist, x, u = shifted_pair(noise=0.0)
    read = interpolation(name)
    grid = read.grid(ref)
    scale = photometric_scale(grid, torch.eye(3, dtype=torch.float64)[:2].expand(10, 2, 3), read)

    def r2(shift):
        return float(photometric_residual(grid, dist, x, u + torch.tensor(shift, dtype=u.dtype), read).pow(2).mean())

    for du in (0.05, 0.1, 0.2):
        excess = sum(r2([s * du * e[0], s * du * e[1]]) - r2([0.0, 0.0]) for s in (1, -1) for e in ((1, 0), (0, 1)))
        assert excess / 4 / scale == pytest.approx(du**2, rel=0.1)


def test_a_smooth_brightness_change_leaves_the_minimum_where_it_was_once_high_passed():
    """The flame's own light and a 10 % gain drift multiply and add to the distorted image smoothly: compared
    raw, the best constant shift moves; high-passed, it stays within 0.03 px of the truth."""
    def drift(x, y):
        return 1.1 + 0.3 * torch.exp(-((x - 40) ** 2 + (y - 32) ** 2) / 400.0)

    ref, dist, x, u = shifted_pair(noise=0.005, gain=drift)
    shifts = torch.linspace(-0.3, 0.3, 61, dtype=torch.float64)

    def best(a, b):
        costs = [rms(photometric_residual(a, b, x, u + torch.tensor([s, 0.0], dtype=u.dtype), BICUBIC)) for s in shifts]
        return float(shifts[int(torch.tensor(costs).argmin())])

    hp = (bandpass(ref, 8.0), bandpass(dist, 8.0))
    assert abs(best(*hp)) <= 0.03
    raw = rms(photometric_residual(ref, dist, x, u, BICUBIC))
    assert raw > 3 * rms(photometric_residual(*hp, x, u, BICUBIC))  # the raw images differ by the brightness itself


@pytest.mark.parametrize("b", [2, 3, 4, 8])
def test_cells_interpolate_a_linear_displacement_field_exactly_between_the_rays(b):
    """Rays of a grid binned b times sit at image points b j + (b - 1) / 2; a displacement linear in the image
    position, known at the 4 rays around a cell, is reproduced exactly at each of the cell's b^2 pixels, which
    tile the image between the rays' points without gaps or overlaps."""
    w = 5

    def field(p):
        return torch.stack([0.3 + 0.02 * p[..., 0] - 0.01 * p[..., 1], -0.2 + 0.015 * p[..., 1]], -1)

    weights, offsets = cell_weights(b, torch.float64)
    seen = []
    for i, j in ((0, 0), (1, 3), (2, 2)):
        corners = torch.tensor([[j, i], [j + 1, i], [j, i + 1], [j + 1, i + 1]], dtype=torch.float64) * b + (b - 1) / 2
        x = cell_origin(torch.tensor([i * w + j]), w, b).double() + offsets
        torch.testing.assert_close(weights @ field(corners), field(x))
        assert bool(((x >= corners[0]) & (x < corners[3])).all())
        seen.append(x)
    assert torch.allclose(weights.sum(-1), torch.ones(b * b, dtype=torch.float64)) and len(offsets) == b * b


def test_the_cached_photometric_scale_is_the_scale_to_the_last_bit_and_computed_once(tmp_path, monkeypatch):
    """Issue 47: a second run on the same images reads each view's scale back; other images compute their own."""
    import nerif.losses.images as images
    from nerif.losses.images import cached_photometric_scale

    g = torch.Generator().manual_seed(3)
    ref = torch.rand((40, 30), generator=g, dtype=torch.float64)
    gain = torch.eye(3, dtype=torch.float64)[:2].expand(10, 2, 3) * 2.0
    direct = photometric_scale(ref, gain, BICUBIC)
    calls = []
    original = images.photometric_scale
    monkeypatch.setattr(images, "photometric_scale", lambda *a, **k: calls.append(1) or original(*a, **k))
    assert cached_photometric_scale(ref, gain, BICUBIC, tmp_path) == direct
    assert cached_photometric_scale(ref, gain, BICUBIC, tmp_path) == direct and len(calls) == 1
    assert cached_photometric_scale(ref * 2, gain, BICUBIC, tmp_path) == pytest.approx(4 * direct)
    assert len(calls) == 2 and cached_photometric_scale(ref, gain, BICUBIC) == direct and len(calls) == 3  # no cache
    assert cached_photometric_scale(ref, gain, interpolation("bspline"), tmp_path) != direct  # another model: its own
