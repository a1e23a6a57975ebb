"""The array cache: computed once per payload, read back after, never shared between payloads."""
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
