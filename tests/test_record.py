"""The realistic chain's two records (:mod:`nerif.sensing.record`): what its views measured and what only it knows,
each cached as arrays and read back field for field; the truth's figures for ``metrics.json``."""
import numpy as np

from nerif.sensing.findings import Findings
from nerif.sensing.record import MeasuredViews, SensingRecord, chain_records


def view(k: int, burner: bool) -> dict:
    rng = np.random.default_rng(k)
    return dict(displacement_px=rng.normal(size=(4, 3, 2)).astype(np.float32), valid=rng.random((4, 3)) > 0.3,
                left_out=rng.integers(0, 3, (4, 3)).astype(np.uint8), reference=rng.integers(0, 255, (8, 6), np.uint8),
                distorted=rng.integers(0, 255, (8, 6), np.uint8), u_true=np.zeros((4, 3, 2), np.float32),
                circle_of_confusion_px=np.float64(1.5 + k), shake_true_px=np.array([0.1 * k, -0.2]),
                occluded_true=np.float64(0.25) if burner else None,
                found={"noise": 0.01 * (k + 1), "clipped": 0.0, "shake_px": [0.1 * k, 0.0]})


def test_each_record_comes_back_from_its_arrays_field_for_field_and_the_truth_holds_no_measurement():
    measured, truth = chain_records([view(0, True), view(1, True)], displacement_rmse_px=0.07)
    back, back_truth = MeasuredViews.from_arrays(measured.arrays()), SensingRecord.from_arrays(truth.arrays())
    for name in ("displacement_px", "valid", "left_out", "reference", "distorted"):
        np.testing.assert_array_equal(getattr(back, name), getattr(measured, name))
    for name in ("u_true", "shake_true_px", "occluded_true"):
        np.testing.assert_array_equal(getattr(back_truth, name), getattr(truth, name))
    assert back_truth.displacement_rmse_px == 0.07
    assert not {"reference", "distorted", "displacement_px", "valid", "found"} & set(truth.arrays())
    assert back.findings() == [Findings(noise=0.01, clipped=0.0, shake_px=[0.0, 0.0]),
                               Findings(noise=0.02, clipped=0.0, shake_px=[0.1, 0.0])]


def test_the_report_gives_the_widest_blur_and_what_the_chain_put_in():
    rep = chain_records([view(0, False), view(1, False)], displacement_rmse_px=0.05)[1].report()
    assert rep["circle_of_confusion_px"] == 2.5 and rep["circle_of_confusion_px_per_view"] == [1.5, 2.5]
    assert rep["shake_true_px"] == [[0.0, -0.2], [0.1, -0.2]] and "occluded_true" not in rep
    assert rep["displacement_rmse_px"] == 0.05


def test_a_view_whose_noise_could_not_be_read_comes_back_without_one_and_weighs_as_the_median():
    """Issue 68's defect: a finding the stage could not make (noise None: too few quiet pixels) was cached as NaN and
    read back as a known noise of NaN, which made every view's weight, the loss and the run NaN. It comes back None,
    shaped findings of the other views intact, and the view weighs as the median of the others' noise."""
    from types import SimpleNamespace

    from nerif.solvers.data_terms import noise_weights

    views = [view(0, False), view(1, False), view(2, False)]
    views[1]["found"] = {**views[1]["found"], "noise": None, "shake_px": None}
    measured, _ = chain_records(views, displacement_rmse_px=0.05)
    found = MeasuredViews.from_arrays(measured.arrays()).findings()
    assert found[1].noise is None and found[1].shake_px is None
    assert found[0].noise == 0.01 and found[2].shake_px == [0.2, 0.0]
    w = noise_weights(SimpleNamespace(findings=found)).numpy()
    # noise 0.01, median 0.02, 0.03: 1/sigma^2 over its mean
    inverse = 1 / np.array([0.01, 0.02, 0.03]) ** 2
    np.testing.assert_allclose(w, inverse / inverse.mean())
    nan_read = [Findings(noise=0.01), Findings(noise=float("nan")), Findings(noise=0.03)]
    np.testing.assert_allclose(noise_weights(SimpleNamespace(findings=nan_read)).numpy(), w)
