"""A view's rigid shift between the exposures (:mod:`nerif.sensing.shake`), read from the flow where no flame
deflects."""
import numpy as np
import torch

from nerif.sensing.imaging import diffraction_blur, warp
from nerif.sensing.measurement import measure_view
from nerif.sensing.patterns import PATTERNS
from nerif.sensing.shake import rigid_shift


def test_a_known_shift_is_recovered_beside_a_flame():
    """A background moved by (0.13, -0.07) px between the exposures, and a flame's displacements (up to 0.8 px) over
    the middle of the view: the shift is read outside the probe box's image to 0.01 px and taken off, and the bulk
    estimate without the box's image is within 0.02 px."""
    H, W = 240, 200
    background = torch.as_tensor(PATTERNS.build({"name": "poisson_disk"}, height=H, width=W, seed=4))
    r, c = torch.meshgrid(torch.arange(H, dtype=torch.float32), torch.arange(W, dtype=torch.float32), indexing="ij")
    flame = torch.exp(-((c - 100) ** 2 + (r - 120) ** 2) / (2 * 25.0**2))
    u = torch.stack([0.8 * flame * (c - 100) / 25, 0.3 * flame], -1)
    shake = torch.tensor([0.13, -0.07])
    # warped bilinearly: PyTorch's bicubic kernel (a = -0.75) shifts a smooth image by 0.17 px where asked for 0.13
    reference = diffraction_blur(background, 2.1).numpy()
    distorted = diffraction_blur(warp(background, u + shake, mode="bilinear"), 2.1).numpy()
    box = np.zeros((60, 50), bool)
    box[10:50, 8:42] = True  # the probe box's image on the ray grid (4 x 4 pixels a ray): the flame is inside it
    m = measure_view(distorted, reference, {"name": "farneback"}, (60, 50), quiet=~box)
    np.testing.assert_allclose(m.found.shake_px, shake.numpy(), atol=0.01)
    truth = u.numpy().reshape(60, 4, 50, 4, 2).mean((1, 3))
    inner = (slice(4, -4), slice(4, -4))
    assert np.abs(m.displacement[inner] - truth[inner]).mean() < 0.03  # the flame's own displacements remain
    bulk, where = rigid_shift(m.displacement + m.found.shake_px, m.valid)
    assert where == "the bulk of the view"
    np.testing.assert_allclose(bulk, shake.numpy(), atol=0.02)
