"""The run's resolution and the peak read through it (:mod:`nerif.resolution`), against closed forms: Gaussian cores
blurred by a known Gaussian, whose peaks follow ``A (w^2 / (w^2 + s^2))^(d / 2)``."""
import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from nerif.resolution import TENT, UNRESOLVED, blur_deficit, effective_resolution_mm, resolved_peak


def _core(widths_vox, amplitude=-0.9, shape=(41, 41, 41), pedestal=0.0):
    """A Gaussian core of ``amplitude`` (sigma: hot is negative) and standard deviations ``widths_vox`` per axis
    (np.inf: flat along that axis), centred on a voxel, on a ``pedestal``."""
    grids = np.meshgrid(*[np.arange(n) - n // 2 for n in shape], indexing="ij")
    r2 = sum(np.zeros(shape) if not np.isfinite(w) else g**2 / w**2 for g, w in zip(grids, widths_vox))
    return pedestal + amplitude * np.exp(-r2 / 2)


def test_the_resolution_is_the_tents_of_the_fields_cell_and_the_rays_spacing():
    """A linear interpolation's tent has the standard deviation cell / sqrt(6); two of them add in quadrature."""
    assert TENT == pytest.approx(1 / np.sqrt(6))
    assert effective_resolution_mm(1.5625, 0.0) == pytest.approx(1.5625 / np.sqrt(6))
    assert effective_resolution_mm(3.0, 4.0) == pytest.approx(5.0 / np.sqrt(6))
    from nerif.geometry import ProbeBox, ray_spacing_mm

    class Seen:  # a camera whose rays (binned pixels) are 2 to the mm at the probe centre, or that faces away
        def __init__(self, per_mm):
            self.per_mm = per_mm

        def pixels_per_mm(self, point):
            return self.per_mm

    box = ProbeBox((4, 4, 4), 2.0)
    assert ray_spacing_mm([Seen(2.0)], box) == 0.5  # four rays across a 2 mm voxel
    assert ray_spacing_mm([Seen(-2.0)], box) == 2.0  # no camera faces the probe: a voxel


@pytest.mark.parametrize("widths, d", [((4.0, 4.0, 4.0), 3), ((3.0, np.inf, 3.0), 2), ((5.0, 8.0, np.inf), 2)])
def test_a_core_wider_than_the_blur_is_read_back_to_first_order(widths, d):
    """A core of w = 3-8 voxels blurred by s = 1 voxel reads (w^2 / (w^2 + s^2))^(d / 2) of its peak (6-15 % cold);
    the peak read through the resolution recovers all but the second-order rest, and never overshoots."""
    s, amplitude = 1.0, -0.9
    blurred = gaussian_filter(_core(widths, amplitude), s, mode="nearest")
    expected = amplitude * np.prod([w / np.hypot(w, s) for w in widths if np.isfinite(w)])
    assert blurred.min() == pytest.approx(expected, rel=1e-3)
    peak = resolved_peak(blurred, resolution_mm=0.5 * s, voxel_mm=0.5, hottest_sigma=-1.05)  # s in mm, 0.5 mm voxels
    assert peak.resolved and all(i == 20 for i, w in zip(peak.index, widths) if np.isfinite(w)) and peak.sigma_field == pytest.approx(blurred.min())
    cold_before, cold_after = amplitude - blurred.min(), amplitude - peak.sigma
    assert 0.0 <= -cold_after < 0.25 * -cold_before or 0.0 <= cold_after < 0.25 * cold_before
    assert peak.sigma >= amplitude - 1e-9  # under-corrects, never beyond the truth


def test_a_flat_field_and_a_smooth_plateau_are_left_as_they_are():
    """No curvature, no correction: a uniform hot region reads its own value."""
    flat = np.full((12, 12, 12), -0.7)
    peak = resolved_peak(flat, 0.8, 1.0, -1.05)
    assert peak.deficit == pytest.approx(0.0, abs=1e-12) and peak.sigma == pytest.approx(-0.7) and peak.resolved
    assert np.abs(blur_deficit(flat, 1.0)).max() < 1e-12


def test_a_core_as_fine_as_the_resolution_is_named_and_left_as_the_field_reads_it():
    """A core of one voxel blurred by one voxel loses far more than the first order can restore (and a spike of
    crossing streaks looks the same): it is flagged and reported as the field has it; a correction never passes the
    prior's bound."""
    blurred = gaussian_filter(_core((1.0, 1.0, 1.0), -0.9), 1.0, mode="nearest")
    peak = resolved_peak(blurred, 1.0, 1.0, -1.05)
    assert not peak.resolved and peak.deficit > UNRESOLVED * abs(peak.sigma_field)
    assert peak.sigma == peak.sigma_field == pytest.approx(blurred.min())
    wide = gaussian_filter(_core((4.0, 4.0, 4.0), -0.99), 1.0, mode="nearest")
    clipped = resolved_peak(wide, 1.0, 1.0, hottest_sigma=-0.9)
    assert clipped.resolved and clipped.sigma == -0.9


def test_a_cores_pedestal_does_not_change_its_correction():
    """The correction is local curvature: a hot core on a uniform hot pedestal is corrected as on ambient gas."""
    core = gaussian_filter(_core((5.0, 5.0, 5.0), -0.4), 1.0, mode="nearest")
    on = gaussian_filter(_core((5.0, 5.0, 5.0), -0.4, pedestal=-0.5), 1.0, mode="nearest")
    a, b = resolved_peak(core, 1.0, 1.0, -1.05), resolved_peak(on, 1.0, 1.0, -1.05)
    assert a.resolved and b.resolved and b.deficit == pytest.approx(a.deficit, rel=1e-6) and b.sigma == pytest.approx(a.sigma - 0.5, abs=1e-6)


def test_exact_deflections_keep_the_fields_peak_and_no_flame_has_no_core():
    """``correct=False`` (exact deflections) weighs the deficit but keeps the field's peak; a field of ambient gas
    (no voxel below -FLAME) is neither corrected nor called unresolved."""
    blurred = gaussian_filter(_core((4.0, 4.0, 4.0), -0.9), 1.0, mode="nearest")
    kept = resolved_peak(blurred, 1.0, 1.0, -1.05, correct=False)
    assert kept.sigma == kept.sigma_field and kept.deficit > 0 and kept.resolved
    faint = gaussian_filter(_core((1.0, 1.0, 1.0), -0.01), 1.0, mode="nearest")
    none = resolved_peak(faint, 1.0, 1.0, -1.05)
    assert none.resolved and none.sigma == none.sigma_field
