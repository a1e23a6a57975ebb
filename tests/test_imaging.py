"""Image formation: warping, diffraction blur, noise, and resampling between pixel grids of one sensor."""
import numpy as np
import torch

from nerif.sensing.imaging import add_noise, diffraction_blur, expose, resample, warp


def _image():
    g = torch.Generator().manual_seed(0)
    return diffraction_blur(torch.rand(40, 50, generator=g, dtype=torch.float64), 4.0)


def test_warp_by_zero_is_identity_and_by_whole_pixels_is_a_shift():
    img = _image()
    torch.testing.assert_close(warp(img, torch.zeros(40, 50, 2, dtype=torch.float64)), img)
    u = torch.zeros(40, 50, 2, dtype=torch.float64)
    u[..., 0], u[..., 1] = 2.0, -1.0  # pixel (r, c) shows the background at (r - 1, c + 2)
    torch.testing.assert_close(warp(img, u)[1:, :-2], img[:-1, 2:])


def test_warp_is_differentiable_in_the_displacements():
    img = _image()[:8, :9]
    u = (0.3 * torch.rand(8, 9, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(1))).requires_grad_()
    assert torch.autograd.gradcheck(lambda v: warp(img, v), (u,))


def test_noise_is_reproducible_and_has_its_variance():
    img = torch.zeros(200, 200)
    a = add_noise(img, 1e-3, torch.Generator().manual_seed(5))
    b = add_noise(img, 1e-3, torch.Generator().manual_seed(5))
    torch.testing.assert_close(a, b)
    assert abs(float(a.var()) / 1e-3 - 1) < 0.05
    assert add_noise(img, 0.0) is img


def test_diffraction_blur_keeps_the_mean_and_lowers_the_contrast():
    img = _image()
    b = diffraction_blur(img, 6.0)
    assert abs(float(b.mean() - img.mean())) < 1e-3 and b.std() < img.std()


def test_resample_takes_block_means_and_keeps_pixel_centres_aligned():
    u = np.random.default_rng(0).random((8, 12, 2)).astype(np.float32)
    small = resample(u, 2, 3)
    np.testing.assert_allclose(small, u.reshape(2, 4, 3, 4, 2).mean((1, 3)), rtol=1e-5)
    ramp = np.broadcast_to(np.arange(3, dtype=np.float32)[None, :, None], (2, 3, 1)).copy()  # column index
    big = resample(ramp, 4, 6)  # twice finer: column j of the fine grid sits at (j + 0.5) / 2 - 0.5 coarse
    np.testing.assert_allclose(big[0, 1:5, 0], [0.25, 0.75, 1.25, 1.75], rtol=1e-6)
    assert resample(u, 8, 12) is u




def test_a_pixel_records_the_share_of_its_area_a_displaced_sharp_edge_covers():
    """A camera's pixel integrates: a dark-bright edge on a pixel boundary, moved 0.3 px, lights 0.3 of the pixel
    beside it (not the bicubic value at its centre); for any displacement, whatever the band of rows."""
    s, H, W = 4, 6, 10
    fine = torch.zeros(H * s, W * s, dtype=torch.float64)
    fine[:, 5 * s:] = 1.0  # bright from the boundary between pixels 4 and 5 on
    torch.testing.assert_close(expose(fine, None, s)[:, 4:6], torch.tensor([[0.0, 1.0]] * H, dtype=torch.float64))
    for shift in (0.3, 0.55, -0.2):
        u = torch.zeros(H, W, 2, dtype=torch.float64)
        u[..., 0] = shift  # pixel x shows the background at x + shift
        seen = expose(fine, u, s, band_rows=4)
        lit = seen[:, 4] if shift > 0 else 1.0 - seen[:, 5]
        torch.testing.assert_close(lit, torch.full((H,), abs(shift), dtype=torch.float64))
        assert float(seen[:, :3].abs().max()) == 0.0 and float((seen[:, 7:] - 1).abs().max()) == 0.0


def test_an_exposure_through_a_displacement_field_reads_a_ramp_at_each_pixels_displaced_centre():
    """On a linear background the pixel's mean is its value at the centre: exact for any smooth displacement."""
    s, H, W = 3, 12, 16
    rows, cols = torch.meshgrid(torch.arange(H * s), torch.arange(W * s), indexing="ij")
    ramp = lambda r, c: 0.02 * c + 0.03 * r  # noqa: E731  [per px of the pixels]
    fine = ramp((rows + 0.5) / s - 0.5, (cols + 0.5) / s - 0.5).double()
    r, c = torch.meshgrid(torch.arange(H), torch.arange(W), indexing="ij")
    u = torch.stack([0.4 * torch.sin(0.3 * r), -0.6 * torch.cos(0.2 * c)], -1).double()
    seen = expose(fine, u, s)
    inner = (slice(2, -2), slice(2, -2))  # away from the border, where points clamp
    torch.testing.assert_close(seen[inner], ramp(r + u[..., 1], c + u[..., 0])[inner].double(), atol=0.02 * 0.4 / s ** 2,
                               rtol=0)
