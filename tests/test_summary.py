"""The multirun table: a row per job with its overrides, only the metric columns that some job has."""
import csv
import json

from omegaconf import OmegaConf

from nerif.io.summary import MultirunSummary, collect, write_tables


def _job(folder, overrides, metrics):
    (folder / ".hydra").mkdir(parents=True)
    (folder / ".hydra" / "overrides.yaml").write_text(OmegaConf.to_yaml(overrides))
    (folder / "metrics.json").write_text(json.dumps(metrics))


def test_a_row_per_job_with_its_overrides(tmp_path):
    _job(tmp_path / "0_hash-discrete", ["encoder=hash"], {"temperature_rmse_K": 14.07, "iterations": 1200})
    _job(tmp_path / "1_cgls-none", ["solver=cgls"], {"temperature_rmse_K": 162.4, "iterations": 200})
    (tmp_path / "2_failed").mkdir()  # no metrics.json: not a row
    rows = collect(tmp_path)
    assert [r["config"] for r in rows] == ["encoder=hash", "solver=cgls"]
    md = write_tables(rows, tmp_path)
    assert md.splitlines()[0] == "| config | T RMSE [K] | iterations |"
    assert md.splitlines()[3] == "| solver=cgls | 162.40 | 200 |"
    table = list(csv.DictReader((tmp_path / "summary.csv").open()))
    assert table[0] == {"config": "encoder=hash", "temperature_rmse_K": "14.07", "iterations": "1200"}


def test_the_hydra_callback_writes_the_tables_beside_the_jobs(tmp_path, capsys):
    _job(tmp_path / "0_x", [], {"deflection_rmse": 1e-5})
    MultirunSummary().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(tmp_path)}}}))
    assert (tmp_path / "summary.md").is_file() and "(defaults)" in capsys.readouterr().out


def test_the_peak_interval_is_a_column_of_its_own(tmp_path):
    """Issue 59: a sweep compares the peak's 2-std interval across its jobs."""
    _job(tmp_path / "0", ["seed=0"], {"T_peak_K": 1533.2, "T_peak_interval_K": [1071.4, 2698.6]})
    md = write_tables(collect(tmp_path), tmp_path)
    assert md.splitlines()[0] == "| config | peak T [K] | its 2-std interval [K] |"
    assert md.splitlines()[2] == "| seed=0 | 1533 | 1071-2699 |"
