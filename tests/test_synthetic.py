"""data/synthetic.py: a phantom seen by a synthetic rig (rays, deflections against their closed form, the cache,
the supersampled rendering, noise, frames, what it allocates)."""
import numpy as np
import pytest
import torch

from nerif.data import DATASETS
from nerif.data.synthetic import _phantom_voxels, allocations, supersampled, synthetic_frames, with_noise

BLOB = {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0, "width_mm": 5.0}
RIG = {"name": "arc", "n_cameras": 3, "binning": 40}


def test_synthetic_scene_keeps_only_rays_through_the_box_and_caches(tmp_path):
    scene = DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0,
                            "render_supersample": 2, "cache_dir": str(tmp_path)})
    assert scene.n_views == 3 and scene.view_start[-1] == len(scene.dirs) == len(scene.eps)
    o = scene.origins[scene.ray_views()]
    assert bool(scene.box.intersect(o, scene.dirs)[2].all())
    assert len(list(tmp_path.glob("synthetic-*.npz"))) == 1
    again = DATASETS.build({"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0,
                            "render_supersample": 2, "cache_dir": str(tmp_path)})
    torch.testing.assert_close(again.eps, scene.eps)
    # the pixel index addresses the ray's own pixel
    cam = scene.cameras[1]
    sl = slice(int(scene.view_start[1]), int(scene.view_start[2]))
    torch.testing.assert_close(scene.dirs[sl], cam.pixel_directions()[scene.pixel[sl]].float())


def test_supersampling_needs_a_phantom_with_a_grid(tmp_path):
    np.save(tmp_path / "T.npy", np.full((8, 8, 8), 400.0))
    ph = {"name": "file", "path": str(tmp_path / "T.npy"), "voxel_mm": 2.0, "T0": 296.15, "n0": 1.00027}
    with pytest.raises(ValueError, match="render_supersample=1"):
        DATASETS.build({"name": "synthetic", "phantom": ph, "rig": RIG, "T_max": 2000.0, "render_supersample": 2})
    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": ph, "rig": RIG, "T_max": 2000.0})
    assert scene.truth_T.shape == (8, 8, 8)


def test_unknown_sensing_is_refused():
    with pytest.raises(ValueError, match="magic.*ideal, perpendicular, realistic"):
        DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": BLOB, "rig": RIG, "T_max": 2000.0,
                        "sensing": "magic"})


def test_ideal_deflections_are_the_blobs_closed_form():
    """The voxel forward model on a 4x finer rendering grid against the line integral of an unbounded Gaussian."""
    from nerif.data.phantoms import gaussian_blob_deflection
    from nerif.physics import delta_from_n, n_from_temperature

    blob = dict(BLOB, T_peak=1200.0, T0=296.15, n0=1.00027)
    scene = DATASETS.build({"name": "synthetic", "phantom": blob, "rig": RIG, "T_max": 2000.0,
                            "render_supersample": 4})
    d_peak = delta_from_n(n_from_temperature(1200.0, 296.15, 1.00027), 1.00027)
    exact = gaussian_blob_deflection(scene.origins[scene.ray_views()].double(), scene.dirs.double(), (0.0, 0.0, 0.0),
                                     5.0, d_peak)
    err = (scene.eps.double() - exact).norm(dim=-1)
    rms = exact.norm(dim=-1).pow(2).mean().sqrt()
    # measured 0.0066 (the box cuts the blob at 3.2 widths); 0.078 without the finer grid, 0.044 for a 5 % scale
    assert float(err.pow(2).mean().sqrt() / rms) < 0.015
    big = exact.norm(dim=-1) > 0.5 * exact.norm(dim=-1).max()
    cos = torch.nn.functional.cosine_similarity(scene.eps.double()[big], exact[big], dim=-1)
    assert float(cos.min()) > 0.99


def test_supersampled_is_the_same_box_on_a_finer_grid():
    fine = supersampled(dict(BLOB, name="gaussian_blob"), 3)
    assert fine.T.shape == (48, 48, 48) and fine.box.voxel_mm == pytest.approx(2.0 / 3)
    from nerif.data.phantoms import PHANTOMS

    coarse = PHANTOMS.build(BLOB)
    np.testing.assert_allclose(fine.box.extent_mm, coarse.box.extent_mm)
    assert fine.T.max() >= coarse.T.max()  # the finer grid samples nearer the blob's centre


@pytest.mark.parametrize("sensing", ["ideal", "perpendicular"])
def test_deflection_noise_has_the_asked_rms_and_is_perpendicular_when_only_that_is_measured(sensing):
    base = {"name": "synthetic", "phantom": BLOB, "rig": RIG, "T_max": 2000.0, "render_supersample": 1,
            "sensing": sensing}
    clean = DATASETS.build(base)
    noisy = DATASETS.build({**base, "deflection_noise": 0.2, "noise_seed": 3})
    n = (noisy.eps - clean.eps).double()
    rms = float(clean.eps.double().norm(dim=-1).pow(2).mean().sqrt())
    assert float(n.norm(dim=-1).pow(2).mean().sqrt()) == pytest.approx(0.2 * rms, rel=1e-4)
    along = (n * clean.dirs.double()).sum(-1).abs().max()
    assert (along < 1e-6 * rms) if sensing == "perpendicular" else (along > 0.05 * rms)
    torch.testing.assert_close(DATASETS.build({**base, "deflection_noise": 0.2, "noise_seed": 3}).eps, noisy.eps)
    with pytest.raises(ValueError, match="data.deflection_noise=-0.1"):
        DATASETS.build({**base, "deflection_noise": -0.1})


def test_frames_are_none_for_a_steady_scene_and_named_when_impossible():
    assert synthetic_frames({"name": "flicker", "time_s": 0.5}) is None
    frames = synthetic_frames({"name": "flicker", "time_s": 0.5}, frames=3, frame_rate_hz=100.0)
    assert [f.time_s for f in frames] == pytest.approx([0.5, 0.51, 0.52])
    with pytest.raises(ValueError, match="does not change in time.*phantom=flicker"):
        synthetic_frames(BLOB, frames=2)
    with pytest.raises(ValueError, match="data.frame_rate_hz=0"):
        synthetic_frames({"name": "flicker", "time_s": 0.0}, frames=2, frame_rate_hz=0)


def test_with_noise_is_the_asked_fraction_and_its_seed_decides():
    eps = torch.randn(500, 3, generator=torch.Generator().manual_seed(0))
    noisy = with_noise(eps, None, 0.1, seed=4)
    rms = float(eps.double().norm(dim=-1).pow(2).mean().sqrt())
    assert float((noisy - eps).double().norm(dim=-1).pow(2).mean().sqrt()) == pytest.approx(0.1 * rms, rel=1e-5)
    torch.testing.assert_close(with_noise(eps, None, 0.1, seed=4), noisy)
    assert not torch.allclose(with_noise(eps, None, 0.1, seed=5), noisy)


def test_what_a_scene_allocates_is_read_from_its_grid_or_its_file_header(tmp_path):
    assert _phantom_voxels(BLOB) == 16**3
    np.save(tmp_path / "T.npy", np.zeros((4, 5, 6)))
    assert _phantom_voxels({"name": "file", "path": str(tmp_path / "T.npy")}) == 120
    assert _phantom_voxels({"name": "file", "path": str(tmp_path / "T.mat")}) is None
    grid = allocations({"phantom": BLOB, "data": {"render_supersample": 2}})
    assert grid[0][2] == 16**3 * 2**3 * 8 * 4  # float64 of the phantom and its deflection field, on the finer grid
    assert allocations({"phantom": {"name": "file", "path": "x.h5"}, "data": {"render_supersample": 2}}) == []
