"""Each view of a capture checked on its own (:mod:`nerif.data.view_check`), on the tiny capture of
``test_capture.py``: one bad view left out and named, too many stop the run."""
import shutil

import numpy as np
import pytest

from nerif.data.capture import capture
from tests.test_capture import FLOW, _read, _swap, _variant, _write, written  # noqa: F401 (a fixture)


@pytest.mark.parametrize("edit, reason", [
    (lambda d: _write(d / "distorted_02.png", np.zeros_like(_read(d / "distorted_02.png"))), "lost the background's texture"),
    (lambda d: _write(d / "distorted_02.png", np.full_like(_read(d / "distorted_02.png"), 255)), "no usable pixel"),
    (lambda d: shutil.copy(d / "reference_02.png", d / "distorted_02.png"), "equals its reference"),
    (lambda d: _swap(d / "distorted_02.png", d / "reference_02.png"), "swapped?"),
])
def test_one_bad_view_is_left_out_named_and_carves_nothing(written, tmp_path, caplog, edit, reason):
    """Issue 38: one view's distorted image black, all saturated, a copy of its reference, or swapped with it erased
    the flame (the visual hull intersects every view's mask) without a word. The view is now left out with one
    warning naming it and why; the others train, and the hull keeps the flame."""
    from nerif.masks import MASKS

    with caplog.at_level("WARNING"):
        cap = capture(_variant(written, tmp_path, None, edit), FLOW, binning=8)
    left = [r.getMessage() for r in caplog.records if "is left out" in r.getMessage()]
    assert len(left) == 1 and left[0].startswith("camera 2 (") and reason in left[0], left
    assert cap.n_views == 5 and cap.heldout.n_views == 1 and all(not c.name.startswith("camera 2 ") for c in cap.cameras)
    flame = written[1].truth_T - written[1].ambient.T0 > 50.0
    assert MASKS.build({"name": "3d"}, scene=cap).volume[flame].all()


def test_a_clean_capture_leaves_no_view_out_and_too_many_bad_views_stop_the_run(written, tmp_path, caplog):
    with caplog.at_level("WARNING"):
        assert capture(str(written[0]), FLOW, binning=8).n_views == 6
    assert "is left out" not in caplog.text

    def blank(d):
        for k in range(4):
            _write(d / f"distorted_{k:02d}.png", np.zeros_like(_read(d / f"distorted_{k:02d}.png")))

    with pytest.raises(ValueError, match="only 2 of the 6 training views are usable .*camera 0 .*lost the background"):
        capture(_variant(written, tmp_path, None, blank), FLOW, binning=8)
