"""Output folders checked for writing before any work, and held by one run at a time (:mod:`nerif.io.folders`)."""
import os

import pytest
from omegaconf import OmegaConf

from nerif.io.folders import LOCK_FILE, OutputFolderCheck, check_writable, run_folder


def test_a_writable_folder_is_made_with_its_parents_and_left_empty(tmp_path):
    folder = tmp_path / "a" / "b"
    check_writable(folder)
    assert folder.is_dir() and not any(folder.iterdir())  # the probe file removed


def test_a_folder_that_cannot_be_written_is_one_sentence_naming_its_key(tmp_path):
    (tmp_path / "file").write_text("")  # a file where the folder's parent should be
    with pytest.raises(ValueError) as e:
        check_writable(tmp_path / "file" / "run", key="hydra.sweep.dir")
    said = str(e.value)
    assert said.startswith(f"the output folder {tmp_path / 'file' / 'run'} cannot be written (")
    assert said.endswith("choose another with hydra.sweep.dir=...")


def test_a_folder_with_an_earlier_run_is_refused_unless_the_run_continues_it(tmp_path):
    with run_folder(tmp_path, continuing=False) as held:  # a new folder: held
        assert held == tmp_path and (tmp_path / LOCK_FILE).read_text() == f"pid {os.getpid()}"
    (tmp_path / "metrics.json").write_text("{}")
    (tmp_path / "checkpoint.pt").write_bytes(b"")
    with pytest.raises(ValueError, match=r"holds an earlier run \(metrics.json, checkpoint.pt\): continue it with "
                                         r"train.resume=auto"):
        with run_folder(tmp_path, continuing=False):
            pass
    with run_folder(tmp_path, continuing=True):  # resumed: the same folder
        pass


def test_a_folder_another_run_is_writing_to_is_refused_naming_that_run(tmp_path):
    """The lock is held on an open file (flock), so a second holder in this process is refused as another
    process would be; released when the first is done."""
    with run_folder(tmp_path, continuing=False):
        with pytest.raises(ValueError, match=f"another nerif run \\(pid {os.getpid()}\\) is writing to {tmp_path}"):
            with run_folder(tmp_path, continuing=True):
                pass
    with run_folder(tmp_path, continuing=True):  # released
        pass


def test_hydra_is_stopped_in_one_line_before_it_makes_a_folder_it_cannot_write(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    config = OmegaConf.create({"hydra": {"run": {"dir": str(tmp_path / "file" / "run")},
                                         "sweep": {"dir": str(tmp_path / "sweep")}}})
    OutputFolderCheck().on_multirun_start(config)  # writable: nothing said
    assert capsys.readouterr().err == ""
    with pytest.raises(SystemExit) as e:
        OutputFolderCheck().on_run_start(config)
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("nerif: error: the output folder") and err.count("\n") == 1 and "hydra.run.dir=" in err
