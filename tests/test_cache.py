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
