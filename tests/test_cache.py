"""The array cache: computed once per payload, read back after, never shared between payloads."""
from pathlib import Path

import numpy as np

from nerif.cache import cached_arrays


def test_computed_once_per_payload_and_read_back(tmp_path):
    calls = []

    def compute(k):
        calls.append(k)
        return {"eps": np.arange(4.0) * k}

    a = cached_arrays(tmp_path, "obs", {"k": 2}, lambda: compute(2))
    b = cached_arrays(tmp_path, "obs", {"k": 2}, lambda: compute(2))
    c = cached_arrays(tmp_path, "obs", {"k": 3}, lambda: compute(3))
    assert calls == [2, 3] and len(list(tmp_path.glob("obs-*.npz"))) == 2
    np.testing.assert_array_equal(b["eps"], a["eps"])
    np.testing.assert_array_equal(c["eps"], [0.0, 3.0, 6.0, 9.0])


def test_a_damaged_entry_is_computed_again_and_an_interrupted_write_is_removed(tmp_path):
    """Issue 28: a corrupt entry failed with BadZipFile on every rerun; a write killed before its rename left a
    ``.tmp`` file that the size bound never counted or removed."""
    import os
    import time

    calls = []
    compute = lambda: calls.append(1) or {"eps": np.arange(3.0)}  # noqa: E731
    cached_arrays(tmp_path, "obs", {"k": 1}, compute)
    entry = next(tmp_path.glob("obs-*.npz"))
    entry.write_bytes(entry.read_bytes()[:40])
    orphan, fresh = tmp_path / ".obs-x.npz.abc.tmp", tmp_path / ".obs-y.npz.def.tmp"
    for f in (orphan, fresh):
        f.write_bytes(b"partial")
    old = time.time() - 7200
    os.utime(orphan, (old, old))
    again = cached_arrays(tmp_path, "obs", {"k": 1}, compute)
    np.testing.assert_array_equal(again["eps"], [0.0, 1.0, 2.0])
    assert calls == [1, 1] and np.load(entry)["eps"].shape == (3,)  # replaced by a whole entry
    assert not orphan.exists() and fresh.exists()  # a write that may still be running is left alone


def test_no_folder_means_no_cache(tmp_path):
    calls = []
    for _ in range(2):
        cached_arrays(None, "obs", {"k": 1}, lambda: calls.append(1) or {"x": np.zeros(1)})
    assert calls == [1, 1]


def test_a_phantom_file_changed_at_the_same_path_is_rendered_again(tmp_path, monkeypatch):
    """Keyed by the field's content, not by the config that names it: the same path with another flame in it
    (or one relative path used from two folders) must not give the first file's observations."""
    from nerif.data import DATASETS
    from nerif.data.phantoms import PHANTOMS

    monkeypatch.chdir(tmp_path)
    blob = PHANTOMS.build({"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 3.0, "width_mm": 7.0}).T
    cfg = {"name": "synthetic", "render_supersample": 1, "T_max": 2000.0, "cache_dir": str(tmp_path / "cache"),
           "rig": {"name": "arc", "n_cameras": 3, "binning": 40},
           "phantom": {"name": "file", "path": "flame.npy", "voxel_mm": 3.0, "T0": 296.15, "n0": 1.00027}}
    np.save("flame.npy", blob)
    hot = DATASETS.build(cfg).eps
    np.save("flame.npy", np.full_like(blob, 296.15))  # now an ambient field, at the same path
    ambient = DATASETS.build(cfg).eps
    assert float(hot.abs().max()) > 1e-5 and float(ambient.abs().max()) == 0.0
    assert len(list((tmp_path / "cache").glob("synthetic-*.npz"))) == 2


def test_the_cache_keeps_the_most_recently_used_entries_within_its_bound(tmp_path, monkeypatch):
    monkeypatch.setenv("NERIF_CACHE_MAX_MB", str(2.5 * 8e5 / 2**20))  # room for two entries of 100,000 doubles
    for k in range(3):
        cached_arrays(tmp_path, "obs", {"k": k}, lambda: {"x": np.random.default_rng(0).random(100_000)})
    cached_arrays(tmp_path, "obs", {"k": 1}, lambda: {"x": np.zeros(1)})  # a hit: 1 is now the most recent
    cached_arrays(tmp_path, "obs", {"k": 3}, lambda: {"x": np.random.default_rng(0).random(100_000)})
    calls = []
    for k in (1, 3, 0, 2):
        cached_arrays(tmp_path, "obs", {"k": k}, lambda: calls.append(k) or {"x": np.zeros(1)})
    assert calls[:2] == [0, 2]  # 1 and 3 were kept; 0 and 2 (least recently used) had gone


def _copy_of_nerif(tmp_path):
    import shutil

    import nerif

    top = tmp_path / "nerif"
    shutil.copytree(Path(nerif.__file__).parent, top, ignore=shutil.ignore_patterns("__pycache__", "*.so"))
    return top


def test_the_forward_model_is_the_import_closure_of_what_renders_observations(tmp_path):
    """The files that decide the synthetic observations are found from the imports (issue 26: a hand-written
    list had left out the deflection renderer and the samplers), and a solver's file is not one of them."""
    from nerif.cache import FORWARD_MODEL_ROOTS, _TOP, import_closure

    files = {str(p.relative_to(_TOP)) for p in import_closure(FORWARD_MODEL_ROOTS)}
    assert {"renderers/deflection.py", "renderers/samplers.py", "renderers/voxel.py", "sensing/realistic.py",
            "sensing/flow.py", "data/synthetic.py", "data/phantoms.py", "geometry/camera.py", "physics.py"} <= files
    assert not {"solvers/neural.py", "solvers/base.py", "reconstruct.py", "app.py", "losses/__init__.py"} & files


def test_a_registry_brings_the_modules_of_its_package_and_subpackages_that_register_into_it(tmp_path):
    """Issue 36: the closure collected only a package's top-level modules, and every one of them: a registry looked
    up brings what registers into it, at any depth, and nothing else of its package."""
    from nerif.cache import import_closure

    top = tmp_path / "nerif"
    files = {"__init__.py": "", "reg.py": "from nerif.registry import Registry\nTHINGS = Registry('t', package='nerif.pkg')\n",
             "user.py": "from nerif.reg import THINGS\nTHINGS.build({'name': 'x'})\n",
             "pkg/__init__.py": "", "pkg/sub/__init__.py": "",
             "pkg/sub/leaf.py": "from nerif.reg import THINGS\n@THINGS.register('x')\ndef x():\n    pass\n",
             "pkg/other.py": "from nerif.registry import Registry\nOTHER = Registry('o', package='nerif.pkg')\n"}
    for name, text in files.items():
        (top / name).parent.mkdir(parents=True, exist_ok=True)
        (top / name).write_text(text)
    found = {str(p.relative_to(top)) for p in import_closure(["nerif.user"], top)}
    assert found == {"__init__.py", "user.py", "reg.py", "pkg/__init__.py", "pkg/sub/__init__.py", "pkg/sub/leaf.py"}


def test_an_edit_to_a_file_of_the_forward_model_misses_the_cache(tmp_path, monkeypatch):
    import nerif.cache as cache

    top = _copy_of_nerif(tmp_path)
    monkeypatch.setattr(cache, "_TOP", top)
    calls = []

    def compute():
        calls.append(1)
        return {"x": np.zeros(2)}

    cached_arrays(tmp_path / "c", "obs", {"k": 1}, compute)
    cached_arrays(tmp_path / "c", "obs", {"k": 1}, compute)
    assert len(calls) == 1
    # outside the forward model: a solver, and the capture reader (its package also holds the phantoms' registry)
    for name in ("solvers/neural.py", "data/capture.py", "data/rig_file.py"):
        (top / name).write_text((top / name).read_text() + "\n# outside\n")
        cache._digest.cache_clear()
        cached_arrays(tmp_path / "c", "obs", {"k": 1}, compute)
    assert len(calls) == 1  # still a hit
    for name in ("renderers/samplers.py", "renderers/deflection.py"):
        (top / name).write_text((top / name).read_text() + "\n# an edit\n")
        cache._digest.cache_clear()  # the code is read once per process: this is the next process
        cached_arrays(tmp_path / "c", "obs", {"k": 1}, compute)
    assert len(calls) == 3  # each edit: a miss, computed again


def test_an_unwritable_cache_folder_is_one_sentence_before_any_work(tmp_path):
    """Issue 28: NERIF_CACHE=/proc/x printed "ERROR - 2"; pointing at a file failed after the observations."""
    import pytest

    (tmp_path / "file").write_text("x")
    calls = []
    for folder in (tmp_path / "file", Path("/proc/nerif-cache")):
        with pytest.raises(ValueError, match=f"the cache folder {folder} .* cannot be written .*data.cache_dir=null"):
            cached_arrays(folder, "obs", {"k": 1}, lambda: calls.append(1) or {"x": np.zeros(1)})
    assert calls == []
