"""The realistic chain's record (:class:`nerif.sensing.record.SensingRecord`): cached as arrays and read back
field for field, and its figures for ``metrics.json``."""
import numpy as np

from nerif.sensing.record import SensingRecord


def view(k: int, burner: bool) -> dict:
    rng = np.random.default_rng(k)
    return dict(displacement_px=rng.normal(size=(4, 3, 2)).astype(np.float32), valid=rng.random((4, 3)) > 0.3,
                left_out=rng.integers(0, 3, (4, 3)).astype(np.uint8), reference=rng.integers(0, 255, (8, 6), np.uint8),
                distorted=rng.integers(0, 255, (8, 6), np.uint8), u_true=np.zeros((4, 3, 2), np.float32),
                u_est=np.zeros((4, 3, 2), np.float32), circle_of_confusion_px=np.float64(1.5 + k),
                shake_true_px=np.array([0.1 * k, -0.2]), occluded_true=np.float64(0.25) if burner else None,
                found={"noise": 0.01 * (k + 1), "clipped": 0.0})


def test_the_record_comes_back_from_its_arrays_field_for_field():
    rec = SensingRecord.of_views([view(0, True), view(1, True)], displacement_rmse_px=0.07)
    back = SensingRecord.from_arrays(rec.arrays())
    for name in ("displacement_px", "valid", "left_out", "reference", "shake_true_px", "occluded_true"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name))
    assert back.displacement_rmse_px == 0.07 and back.found["noise"].tolist() == [0.01, 0.02]


def test_the_report_gives_the_widest_blur_and_what_the_chain_put_in():
    rep = SensingRecord.of_views([view(0, False), view(1, False)], displacement_rmse_px=0.05).report()
    assert rep["circle_of_confusion_px"] == 2.5 and rep["circle_of_confusion_px_per_view"] == [1.5, 2.5]
    assert rep["shake_true_px"] == [[0.0, -0.2], [0.1, -0.2]] and "occluded_true" not in rep
    assert rep["displacement_rmse_px"] == 0.05
