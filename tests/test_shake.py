"""A view's rigid shift between the exposures (:mod:`nerif.sensing.shake`), read from the flow where no flame
deflects."""
import numpy as np
import torch

from nerif.sensing.imaging import diffraction_blur, expose
from nerif.sensing.measurement import measure_view
from nerif.sensing.patterns import PATTERNS
from nerif.sensing.shake import rigid_shift


def test_a_known_shift_is_recovered_beside_a_flame():
    """A background moved by (0.13, -0.07) px between the exposures (the pixels integrating it, as the realistic
    chain renders it), and a flame's displacements (up to 0.8 px) over the middle of the view: the shift the images
    hold is read from them outside the probe box's image to 0.005 px (``shake_images_px``; the flow reads 1.1-1.2x
    it); the flow's own reading (``shake_px``) is what is taken off its displacements, and the bulk estimate without
    the box's image is within 0.03 px of it."""
    H, W, k = 240, 200, 4
    background = torch.as_tensor(PATTERNS.build({"name": "poisson_disk"}, height=H, width=W, seed=4, samples=k))
    background = diffraction_blur(background, 2.1 * k)
    r, c = torch.meshgrid(torch.arange(H, dtype=torch.float32), torch.arange(W, dtype=torch.float32), indexing="ij")
    flame = torch.exp(-((c - 100) ** 2 + (r - 120) ** 2) / (2 * 25.0**2))
    u = torch.stack([0.8 * flame * (c - 100) / 25, 0.3 * flame], -1)
    shake = torch.tensor([0.13, -0.07])
    reference, distorted = expose(background, None, k).numpy(), expose(background, u + shake, k).numpy()
    box = np.zeros((60, 50), bool)
    box[10:50, 8:42] = True  # the probe box's image on the ray grid (4 x 4 pixels a ray): the flame is inside it
    m = measure_view(distorted, reference, {"name": "farneback"}, (60, 50), quiet=~box)
    np.testing.assert_allclose(m.found.shake_images_px, shake.numpy(), atol=0.005)
    flow = np.asarray(m.found.shake_px)
    assert np.all(np.abs(flow - shake.numpy()) > 0.005)  # the flow's gain: its reading is not the images'
    truth = u.numpy().reshape(60, 4, 50, 4, 2).mean((1, 3))
    inner = (slice(4, -4), slice(4, -4))
    assert np.abs(m.displacement[inner] - truth[inner]).mean() < 0.03  # the flame's own displacements remain
    bulk, where = rigid_shift(m.displacement + flow, m.valid)
    assert where == "the bulk of the view"
    np.testing.assert_allclose(bulk, flow, atol=0.03)


def test_the_shift_the_images_hold_is_read_through_a_gain_ramp_and_the_flames_light():
    """The same shift read from the images alone (:func:`~nerif.sensing.shake.photometric_shift`), the distorted
    exposure 1 -> 1.1 times brighter across the view and a smooth glow of 30 % on it: within 0.005 px of the
    shift, from a start 0.05 px off; fewer pixels than a ray grid needs: the start, unmoved."""
    from nerif.sensing.shake import MIN_QUIET, photometric_shift

    H, W, k = 200, 240, 4
    background = diffraction_blur(torch.as_tensor(PATTERNS.build({"name": "poisson_disk"}, height=H, width=W, seed=2,
                                                                  samples=k)), 2.5 * k)
    shake = torch.tensor([-0.11, 0.17])
    reference = expose(background, None, k).numpy()
    ramp = np.linspace(1.0, 1.1, W, dtype=np.float32)[None, :]
    r, c = np.mgrid[0:H, 0:W]
    glow = 0.3 * np.exp(-((c - 120) ** 2 + (r - 100) ** 2) / (2 * 40.0**2)).astype(np.float32)
    distorted = expose(background, shake.expand(H, W, 2), k).numpy() * ramp + glow
    where = np.ones((H, W), bool)
    found = photometric_shift(distorted, reference, where, shake.numpy() + 0.05, 2.0)
    np.testing.assert_allclose(found, shake.numpy(), atol=0.005)
    few = np.zeros((H, W), bool)
    few[100, 100:100 + MIN_QUIET - 1] = True
    np.testing.assert_array_equal(photometric_shift(distorted, reference, few, np.array([0.3, 0.0]), 2.0), [0.3, 0.0])
