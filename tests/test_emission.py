"""The flame's own light as a camera focused on the background sees it (:mod:`nerif.sensing.emission`)."""
import numpy as np
import torch

from nerif.geometry import RIGS, ProbeBox
from nerif.sensing.emission import flame_light


def spread(img: np.ndarray) -> float:
    """The light's RMS width along the rows [px]."""
    profile = img.sum(0)
    x = np.arange(len(profile))
    mean = (x * profile).sum() / profile.sum()
    return float(np.sqrt(((x - mean) ** 2 * profile).sum() / profile.sum()))


def test_a_voxel_of_light_is_blurred_by_a_quarter_of_the_circle_of_confusion():
    """One glowing voxel, its projection of spread s0, seen through a circle of confusion 16 px across: its spread
    becomes sqrt(s0^2 + 4^2) (a uniform disc of diameter d has a standard deviation of d/4 per axis), its peak 1."""
    box = ProbeBox((16, 16, 16), 2.0)
    delta = torch.zeros(16, 16, 16, dtype=torch.float64)
    delta[8, 8, 8] = 1.0
    cam = RIGS.build({"name": "arc", "n_cameras": 2, "binning": 8})[0]
    sharp, blurred = flame_light(delta, box, cam, 0.0), flame_light(delta, box, cam, 16.0)
    assert sharp.max() == blurred.max() == 1.0
    assert abs(spread(blurred) - np.hypot(spread(sharp), 4.0)) < 0.1 * 4.0
