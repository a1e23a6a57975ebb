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


def test_the_sign_check_says_swapped_only_when_the_views_agree():
    """Issue 37: a capture whose flow failed in some views (the flame's own light) was refused as 'swapped'. Every
    view reversed is swapping; a third of them reversed is a measurement failing in those views, named."""
    from dataclasses import replace

    import pytest

    from nerif.data import DATASETS
    from nerif.data.diagnostics import check_sign

    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "sensing": "perpendicular",
                            "phantom": {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0,
                                        "width_mm": 5.0, "T_peak": 1500.0},
                            "rig": {"name": "arc", "n_cameras": 6, "binning": 40}, "T_max": 2000.0})
    assert check_sign(scene, None) == []
    with pytest.raises(ValueError, match="in 6 of 6 views: their sign looks reversed"):
        check_sign(replace(scene, eps=-scene.eps), None)
    eps = scene.eps.clone()
    for v in range(4):  # four views reversed outright, two as measured
        eps[scene.view_slice(v)] *= -1
    with pytest.raises(ValueError, match="the views disagree: camera 00 .*, camera 03 .* show cold gas, camera 04 .*"
                                         "a hot flame; the displacements of the first look wrong") as e:
        check_sign(replace(scene, eps=eps), None)
    assert "swapped" not in str(e.value) and "reversed" not in str(e.value)


def test_every_volume_a_solver_shows_is_written_beside_sigma_and_its_temperature(tmp_path, monkeypatch):
    """Issue 47: the outputs took sigma alone. A solver's :meth:`volumes` (an uncertainty, say) reach
    ``reconstruction.npz`` and ``.vti`` as they are, beside sigma and the temperature derived from it."""
    import numpy as np

    from nerif.app import run
    from nerif.solvers.base import IterativeSolver
    from tests.helpers import tiny_config

    def volumes(self):
        sigma = self.reconstruction()
        return {"sigma": sigma, "sigma_std": np.full_like(sigma, 0.25)}

    monkeypatch.setattr(IterativeSolver, "volumes", volumes)
    run(tiny_config("train.iterations=2"), tmp_path)
    with np.load(tmp_path / "reconstruction.npz") as f:
        assert {"sigma", "sigma_std", "T"} <= set(f.files)
        assert np.all(f["sigma_std"] == 0.25) and f["sigma_std"].shape == f["sigma"].shape
    assert 'Name="sigma_std"' in (tmp_path / "reconstruction.vti").read_text()
