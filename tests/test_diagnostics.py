"""Each view of a capture checked on its own (:mod:`nerif.data.diagnostics`), on the tiny capture of
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
    assert len(left) == 1 and left[0].startswith("camera 02 (") and reason in left[0], left
    assert cap.n_views == 5 and cap.heldout.n_views == 1 and all(not c.name.startswith("camera 02 ") for c in cap.cameras)
    flame = written[1].truth_T - written[1].ambient.T0 > 50.0
    assert MASKS.build({"name": "3d"}, scene=cap).volume[flame].all()


def test_a_clean_capture_leaves_no_view_out_and_too_many_bad_views_stop_the_run(written, tmp_path, caplog):
    with caplog.at_level("WARNING"):
        assert capture(str(written[0]), FLOW, binning=8).n_views == 6
    assert "is left out" not in caplog.text

    def blank(d):
        for k in range(4):
            _write(d / f"distorted_{k:02d}.png", np.zeros_like(_read(d / f"distorted_{k:02d}.png")))

    with pytest.raises(ValueError, match="only 2 of the 6 training views are usable .*camera 00 .*lost the background"):
        capture(_variant(written, tmp_path, None, blank), FLOW, binning=8)


def _quality_warnings(caplog) -> str:
    return " ".join(r.getMessage() for r in caplog.records if r.levelname == "WARNING")


def test_a_probe_box_smaller_than_the_flame_is_said_and_a_clean_one_is_not(written, tmp_path, caplog):
    """Issue 38: a probe box smaller than the flame was reconstructed as ambient gas, with an INFO line only. Outside
    the box's image the flow reads its noise (a sixth of the flame's displacements here and on the shared captures);
    with the box cut to a third of its width it reads the flame there (about as large as inside)."""
    with caplog.at_level("WARNING"):
        capture(str(written[0]), FLOW, binning=8)
    assert "outside the probe box's image" not in _quality_warnings(caplog)
    caplog.clear()
    shape = written[1].box.shape

    def narrow(rig):
        rig["probe"]["shape"] = [max(2, shape[0] // 3), shape[1], max(2, shape[2] // 3)]

    with caplog.at_level("WARNING"):
        capture(_variant(written, tmp_path, narrow), FLOW, binning=8)
    said = _quality_warnings(caplog)
    assert "views see the flame outside the probe box's image" in said and "enlarge probe.shape" in said, said


def test_clipped_exposures_are_said_with_their_share(written, tmp_path, caplog):
    """Issue 38: a 2x gain clipped at full scale passed without a word (3.6x the error). The clipped dots' centres
    keep their texture around them, so no pixel is left out, but the share at full scale is reported."""
    def gain(d):
        for f in d.glob("*.png"):
            img = _read(f)
            _write(f, np.clip(img.astype(np.float32) * 2, 0, 255).astype(img.dtype))

    with caplog.at_level("WARNING"):
        cap = capture(_variant(written, tmp_path, None, gain), FLOW, binning=8)
    said = _quality_warnings(caplog)
    share = max(f.clipped for f in cap.findings)
    assert share > 0.05 and f"up to {100 * share:.0f} % of the pixels are at full scale" in said, said
    assert "is left out" not in said


def test_every_view_failing_alike_is_said_once(written, tmp_path):
    """Every distorted image a copy of its reference: one sentence for the capture, not one reason per camera."""
    def no_flame(d):
        for k in range(7):
            shutil.copy(d / f"reference_{k:02d}.png", d / f"distorted_{k:02d}.png")

    with pytest.raises(ValueError, match="^no view is usable: in every view, its distorted image equals its "
                                         "reference") as e:
        capture(_variant(written, tmp_path, None, no_flame), FLOW, binning=8)
    assert "camera 1" not in str(e.value)
