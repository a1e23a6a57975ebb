"""One reconstruction: what the log warns of, the run's results say too (metrics.json and the summary line)."""
import json
import logging

from nerif.reconstruct import WarningRecords


def test_warnings_are_recorded_while_installed_and_only_warnings():
    with WarningRecords() as records:
        logging.getLogger("nerif.solvers.base").warning("the flame crosses %s", "+z")
        logging.getLogger("nerif.data").info("an information")
        logging.getLogger("elsewhere").warning("not nerif's")
    logging.getLogger("nerif.data").warning("after the run")
    assert records.messages == ["the flame crosses +z"]


def test_a_warning_logged_deep_in_a_run_reaches_metrics_and_the_summary_line(tmp_path, monkeypatch, capsys):
    """Issue 35: "the visual hull covers every face" was in nerif.log only; metrics.json had no warnings."""
    from nerif.app import run
    from tests.helpers import tiny_config

    # the data say the flame crosses the x faces, where loss.ambient_faces holds sigma = 0: the solver warns
    monkeypatch.setattr("nerif.solvers.base.ambient_faces", lambda *a: (["-x", "+x"], ["-x", "+x"]))
    m = run(tiny_config("loss.ambient_faces=[x]"), tmp_path)
    expected = "loss.ambient_faces holds sigma = 0 on +x, -x, which the flame crosses: use loss.ambient_faces=auto"
    assert m["warnings"] == [expected]
    assert json.loads((tmp_path / "metrics.json").read_text())["warnings"] == [expected]
    assert f"WARNING: {expected}" in capsys.readouterr().out.splitlines()[-1]
