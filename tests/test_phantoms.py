import numpy as np
import pytest
import scipy.io

from nerif.data.phantoms import PHANTOMS, gaussian_blob, phantom5, phantom5_temperature
from nerif.physics import n_from_temperature


def test_phantom5_by_hand():
    # at (0, 50, 0) the central blob's g = exp(-(0 - 0.9)^2); the side blobs are 25 mm away: exp(-14.3)
    side = np.exp(-((3 * 25**2 / 400 - 0.9) ** 2))
    assert phantom5_temperature(0.0, 50.0, 0.0) == pytest.approx(296.15 + 1196.85 * np.exp(-0.81) + 2 * 696.85 * side)
    ph = phantom5(shape=(36, 50, 36), voxel_mm=2.0)
    assert ph.T.shape == (36, 50, 36) and ph.box.extent_mm.tolist() == [72.0, 100.0, 72.0]
    # symmetric in x and z, ambient far from the blobs
    np.testing.assert_allclose(ph.T, ph.T[::-1], rtol=1e-12)
    np.testing.assert_allclose(ph.T, ph.T[:, :, ::-1], rtol=1e-12)
    assert ph.T[0, 25, 0] == pytest.approx(296.15, abs=1e-6)


def test_phantom5_honours_its_ambient_temperature():
    """``phantom.T0=300`` moves the ambient and keeps the flame's rises (before, T0 was ignored and the whole box,
    at 296.15 K, counted as flame)."""
    a, b = phantom5(shape=(18, 25, 18), voxel_mm=4.0), phantom5(shape=(18, 25, 18), voxel_mm=4.0, T0=300.0)
    assert b.T0 == 300.0 and b.T[0, 12, 0] == pytest.approx(300.0, abs=1e-6)
    np.testing.assert_allclose(b.T - 300.0, a.T - 296.15, atol=1e-9)


def test_gaussian_blob_peak():
    ph = gaussian_blob(shape=(21, 21, 21), voxel_mm=1.0, T_peak=1500.0)
    assert ph.T.max() == pytest.approx(1500.0, rel=1e-9)
    assert ph.delta.min() == pytest.approx(n_from_temperature(1500.0, 296.15, 1.00027) / 1.00027 - 1, rel=1e-9)


@pytest.mark.parametrize("suffix", [".npy", ".npz", ".mat", ".h5"])
def test_volume_files_round_trip(tmp_path, suffix):
    T = 296.15 + 500 * np.random.rand(6, 8, 5)
    path = tmp_path / f"flame{suffix}"
    if suffix == ".npy":
        np.save(path, T)
    elif suffix == ".npz":
        np.savez(path, T=T)
    elif suffix == ".mat":
        scipy.io.savemat(path, {"T": T})
    else:
        import h5py

        with h5py.File(path, "w") as f:
            f["T"] = T
    ph = PHANTOMS.build({"name": "file", "path": str(path), "voxel_mm": 0.5, "T0": 296.15, "n0": 1.00027})
    np.testing.assert_allclose(ph.T, T)
    assert ph.box.shape == (6, 8, 5) and ph.box.voxel_mm == 0.5


def test_refractive_index_files_become_temperatures(tmp_path):
    T = np.full((4, 4, 4), 900.0)
    np.save(tmp_path / "n.npy", n_from_temperature(T, 296.15, 1.00027))
    ph = PHANTOMS.build({"name": "file", "path": str(tmp_path / "n.npy"), "voxel_mm": 1, "T0": 296.15,
                         "n0": 1.00027, "quantity": "n"})
    np.testing.assert_allclose(ph.T, 900.0, rtol=1e-9)


@pytest.mark.parametrize("volume, message", [
    (np.full((4, 4), 300.0), "rank 3"),
    (np.where(np.arange(64).reshape(4, 4, 4) == 5, np.nan, 300.0), "NaN"),
    (np.full((4, 4, 4), 0.5), "below 1 K"),
])
def test_bad_volume_files_fail_clearly(tmp_path, volume, message):
    np.save(tmp_path / "v.npy", volume)
    with pytest.raises(ValueError, match=message):
        PHANTOMS.build({"name": "file", "path": str(tmp_path / "v.npy"), "voxel_mm": 1, "T0": 296.15, "n0": 1.00027})


@pytest.mark.parametrize("name, content", [
    ("garbage.npy", b"this is not an array at all" * 10),
    ("truncated.npy", None),
    ("pickled.npy", "pickle"),
    ("garbage.npz", b"PK\x03\x04 not a zip"),
    ("garbage.h5", b"\x89HDF nope"),
])
def test_unreadable_volume_files_are_one_sentence_naming_the_file(tmp_path, name, content):
    path = tmp_path / name
    if content is None:
        np.save(path, np.ones((8, 8, 8)))
        path.write_bytes(path.read_bytes()[:200])
    elif content == "pickle":
        np.save(path, np.array([{"T": 300.0}], dtype=object), allow_pickle=True)
    else:
        path.write_bytes(content)
    with pytest.raises(ValueError) as e:
        PHANTOMS.build({"name": "file", "path": str(path), "voxel_mm": 1, "T0": 296.15, "n0": 1.00027})
    assert str(e.value).startswith(f"cannot read volume file {path}: it is not a valid {path.suffix} file")
    assert "allow_pickle" not in str(e.value)


def test_missing_file_and_ambiguous_archive(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        PHANTOMS.build({"name": "file", "path": str(tmp_path / "nope.npy"), "voxel_mm": 1, "T0": 296, "n0": 1.0003})
    np.savez(tmp_path / "two.npz", a=np.ones((2, 2, 2)), b=np.ones((2, 2, 2)))
    with pytest.raises(ValueError, match="phantom.key"):
        PHANTOMS.build({"name": "file", "path": str(tmp_path / "two.npz"), "voxel_mm": 1, "T0": 296, "n0": 1.0003})


def test_axisymmetric_flame_is_symmetric_about_the_axis_and_reads_a_profile_table(tmp_path):
    from nerif.data.phantoms import lifted_jet_profile

    ph = PHANTOMS.build({"name": "axisymmetric", "shape": [20, 50, 20], "voxel_mm": 2.0})
    np.testing.assert_allclose(ph.T, ph.T.transpose(2, 1, 0), rtol=1e-12)  # x <-> z
    np.testing.assert_allclose(ph.T, ph.T[::-1], rtol=1e-12)  # x -> -x
    assert ph.T.max() > 1500 and ph.T[:, :3].max() < 400  # lifted: cold below the flame base
    r, y = np.linspace(0, 40, 161), np.linspace(-40, 40, 161)
    R, Y = np.meshgrid(r, y, indexing="ij")
    np.savez(tmp_path / "profile.npz", r_mm=r, y_mm=y, T=lifted_jet_profile(R, Y, 296.15, 1800.0))
    tab = PHANTOMS.build({"name": "axisymmetric", "shape": [20, 50, 20], "voxel_mm": 2.0,
                          "profile": str(tmp_path / "profile.npz")})
    inside = np.abs(ph.box.centres()[..., 1]) < 39  # the table covers |y| < 40 mm
    assert np.abs(tab.T - ph.T)[inside].max() < 40  # linear interpolation of a 0.25 mm table
    np.savez(tmp_path / "bad.npz", r_mm=r, y_mm=y, T=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="T must be"):
        PHANTOMS.build({"name": "axisymmetric", "profile": str(tmp_path / "bad.npz")})


def test_turbulent_plume_is_seeded_clipped_and_has_a_minus_five_thirds_spectrum():
    from nerif.data.phantoms import kolmogorov_field

    a = PHANTOMS.build({"name": "turbulent_plume", "seed": 1})
    b = PHANTOMS.build({"name": "turbulent_plume", "seed": 1})
    c = PHANTOMS.build({"name": "turbulent_plume", "seed": 2})
    np.testing.assert_array_equal(a.T, b.T)
    assert np.abs(a.T - c.T).max() > 50
    assert a.T.min() >= a.T0 and a.T.max() <= 2200.0
    assert 0.05 < ((a.T - a.T0) > 1).mean() < 0.6  # a plume in ambient air, not a filled box
    # shell-averaged energy spectrum E(k) ~ 4 pi k^2 |F(k)|^2 falls as k^(-5/3) below the largest scale
    n, h = 64, 1.0
    f = kolmogorov_field((n, n, n), h, 0, largest_mm=16.0)
    P = np.abs(np.fft.fftn(f)) ** 2
    k = np.sqrt(sum(g**2 for g in np.meshgrid(*[np.fft.fftfreq(n, h)] * 3, indexing="ij")))
    bins = np.linspace(1 / 12, 0.4, 12)
    kc = 0.5 * (bins[1:] + bins[:-1])
    E = np.array([P[(k >= lo) & (k < hi)].mean() for lo, hi in zip(bins[:-1], bins[1:])]) * kc**2
    slope = np.polyfit(np.log(kc), np.log(E), 1)[0]
    assert abs(slope + 5 / 3) < 0.15, slope


def test_the_flickering_flame_is_the_axisymmetric_one_puffing_periodically():
    """``phantom=flicker``: without amplitude it is the axisymmetric flame; a period later it is the same state;
    half a period later it differs; each state stays symmetric about the axis."""
    common = {"shape": [20, 50, 20], "voxel_mm": 2.0}
    still = PHANTOMS.build({"name": "flicker", "amplitude": 0.0, "time_s": 0.03, **common})
    np.testing.assert_allclose(still.T, PHANTOMS.build({"name": "axisymmetric", **common}).T, rtol=0, atol=1e-9)
    t0 = PHANTOMS.build({"name": "flicker", "time_s": 0.01, **common}).T
    period = PHANTOMS.build({"name": "flicker", "time_s": 0.01 + 1 / 12.0, **common}).T
    half = PHANTOMS.build({"name": "flicker", "time_s": 0.01 + 0.5 / 12.0, **common}).T
    np.testing.assert_allclose(period, t0, rtol=0, atol=1e-6)
    assert np.abs(half - t0).max() > 100.0  # K: the bulges moved by half a wavelength
    np.testing.assert_allclose(t0, t0[::-1, :, ::-1], rtol=0, atol=1e-9)
