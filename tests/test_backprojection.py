"""2-D masks from deflections, their holes, the visual hull, and the faces the flame crosses."""
import warnings

import numpy as np
import pytest

from nerif.configs import compose, group
from nerif.data import DATASETS
from nerif.geometry import FACES, box_faces
from nerif.masks import MASKS, Masks
from nerif.masks.backprojection import ambient_faces, back_project, crossed_faces, deflection_masks, fill_holes
from tests.helpers import solver, tiny_config

SPHERE = {"name": "gaussian_blob", "shape": [24, 24, 24], "voxel_mm": 2.0, "width_mm": 5.0, "T_peak": 1500.0}


@pytest.fixture(scope="module")
def scene():
    return DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                           "T_max": 2000.0})


def test_3d_mask_contains_the_blob_and_lies_inside_the_visual_hull(scene):
    masks = MASKS.build({"name": "3d", "threshold": 1e-3, "radius_px": 2}, scene=scene)
    flame = scene.truth_T - scene.ambient.T0 > 10.0
    assert flame.sum() > 50 and masks.volume[flame].all()
    # every valid voxel projects inside every view's 2-D mask (visual hull)
    centres = scene.box.centres()[masks.volume]
    for cam, img in zip(scene.cameras, masks.images):
        uv = np.floor(cam.project(centres)).astype(int)
        assert img[uv[:, 1], uv[:, 0]].all()
    assert masks.volume.mean() < 0.5  # it does cut away empty space


def test_fewer_cameras_required_only_grows_the_mask(scene):
    images = deflection_masks(scene, 1e-3, 2)
    sizes = [back_project(scene.box, scene.cameras, images, n).sum() for n in (6, 5, 3, 1)]
    assert sizes == sorted(sizes) and sizes[-1] > sizes[0]
    a, b = (back_project(scene.box, scene.cameras, images, n) for n in (6, 4))
    assert not (a & ~b).any()


def test_2d_masks_fill_the_quiet_core_of_a_symmetric_flame(scene):
    img = deflection_masks(scene, 1e-3, 0)[0]
    cam = scene.cameras[0]
    u, v = np.floor(cam.project(np.zeros(3))).astype(int)
    assert img[v, u]  # the central ray is barely deflected but lies inside the silhouette


def test_a_view_with_no_signal_warns_and_gets_an_empty_mask(scene):
    quiet = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                            "T_max": 2000.0})
    sl = slice(int(quiet.view_start[2]), int(quiet.view_start[3]))
    quiet.eps[sl] = 0.0
    with pytest.warns(UserWarning, match="camera 02 .* 2-D mask is empty"):
        masks = MASKS.build({"name": "2d", "threshold": 1e-3, "radius_px": 2}, scene=quiet)
    assert len(masks.inside[2]) == 0
    quiet.eps[:] = 0.0  # every view silent: one warning naming them all, not one per view
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        MASKS.build({"name": "2d", "threshold": 1e-3, "radius_px": 2}, scene=quiet)
    assert len(caught) == 1 and str(caught[0].message).startswith("camera 00 (0.0 deg), camera 01 (33.0 deg)")
    assert str(caught[0].message).endswith("their 2-D masks are empty")


def test_a_view_with_no_signal_is_left_out_of_the_visual_hull(scene):
    quiet = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE,
                            "rig": {"name": "arc", "n_cameras": 6, "binning": 20}, "T_max": 2000.0})
    quiet.eps[quiet.view_slice(2)] = 0.0  # a camera that failed: before, its empty mask carved the whole hull
    with pytest.warns(UserWarning, match="camera 02 .* 2-D mask is empty"):
        masks = MASKS.build({"name": "3d"}, scene=quiet)
    others = MASKS.build({"name": "3d"}, scene=quiet.select_views([0, 1, 3, 4, 5]))
    assert masks.volume.any() and np.array_equal(masks.volume, others.volume)


def test_an_empty_3d_mask_is_a_clear_error(scene):
    silent = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": SPHERE, "rig": {"name": "arc", "n_cameras": 6, "binning": 20},
                             "T_max": 2000.0})
    silent.eps.zero_()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ValueError, match="3-D mask is empty"):
            MASKS.build({"name": "3d"}, scene=silent)


def test_holes_open_to_one_side_are_filled_and_background_reaching_two_sides_is_not():
    region = np.zeros((12, 14), bool)
    region[1:11, 1:13] = True  # the box's image, inside the picture
    u = np.zeros_like(region)
    u[4:11, 3:5] = u[4:11, 8:10] = u[4:6, 3:10] = True  # an upside-down U cut by the bottom edge
    filled = fill_holes(u, region)
    assert filled[6:11, 5:8].all()  # its open core (touches the bottom edge only) is filled
    assert not filled[1:4].any() and not filled[:, 10:].any()  # ambient around it reaches several sides
    ring = np.zeros_like(region)
    ring[3:9, 3:9] = True
    ring[5:7, 5:7] = False
    assert fill_holes(ring, region)[5:7, 5:7].all()  # an enclosed core, as before
    stairs = region.copy()
    stairs[10, 1:7] = False  # a slanted bottom edge, one pixel higher on the left: the notch meets a step of it
    notch = np.ones_like(region) & stairs
    notch[5:11, 7:9] = False  # reaches the bottom edge right at the step, so one pixel also has outside to its left
    assert fill_holes(notch, stairs)[5:11, 7:9].all()  # still one side (bottom): a step is no second side
    two = np.zeros_like(region)
    two[1:11, 3:5] = two[1:11, 8:10] = True  # two flames through the whole height: the gap is ambient
    assert not fill_holes(two, region)[:, 5:8].any()


@pytest.mark.parametrize("phantom, crossed", [
    ({"name": "phantom5"}, ["-y", "+y", "-z", "+z"]),  # its lobes are cut by the y and z faces
    ({"name": "gaussian_blob"}, []),  # centred: every face ambient
    ({"name": "axisymmetric"}, ["+y"]),  # hot at its top only
])
def test_the_faces_the_flame_crosses_are_the_hot_faces_of_the_phantom(phantom, crossed):
    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": phantom, "T_max": 2000.0,
                            "rig": {"name": "arc", "n_cameras": 12, "binning": 8}, "sensing": "perpendicular"})
    masks = MASKS.build({"name": "3d"}, scene=scene)
    hot = [f for f in FACES for a, s in box_faces([f])
           if (np.take(scene.truth_T, 0 if s < 0 else -1, axis=a) - scene.ambient.T0).max() > 50.0]
    assert crossed_faces(masks.volume, 0.1) == crossed == hot
    ambient, found = ambient_faces("auto", scene, masks, 0.1, ["x"])
    assert found == crossed and sorted(ambient + crossed) == sorted(FACES)
    assert ambient_faces("auto", scene, MASKS.build({"name": "none"}, scene=scene), 0.1, ["x"]) == (ambient, crossed)
    assert ambient_faces(["x"], scene, masks, 0.1, ["x"]) == (["-x", "+x"], crossed)
    everywhere = Masks(volume=np.ones(scene.box.shape, bool))  # a hull that covers every face: the data do not tell
    assert ambient_faces("auto", scene, everywhere, 0.1, fallback=["z"]) == (["-z", "+z"], list(FACES))


def test_the_visual_hull_keeps_the_hot_gas_where_the_box_cuts_phantom5():
    """Phantom 5's lobes are hollow shells cut by the y and z faces: their barely deflected cores reach the edge of
    the box's image as notches. Left open (the fill of 2-D holes before), the notches carved 10 % of the flame
    (|sigma| > 1 % of its peak) out of the hull, at 993 K on the z faces, and perpendicular-only data then lost the
    level (188 K with mask=3d against 16 K with mask=2d, default scene)."""
    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "phantom": {"name": "phantom5"},
                            "T_max": 2000.0, "rig": {"name": "arc", "n_cameras": 12, "binning": 8},
                            "sensing": "perpendicular"})
    masks = MASKS.build({"name": "3d"}, scene=scene)
    sigma = np.abs(scene.ambient.sigma_from_temperature(scene.truth_T))
    flame = sigma > 0.01 * sigma.max()
    assert masks.volume[flame].all()
    assert masks.volume.mean() < 0.65  # and it still cuts away a third of the box (61 % kept)



def test_noise_neither_fills_the_masks_nor_hides_the_ambient_faces(scene):
    """Gaussian deflection noise of 20 % of the RMS deflection: the relative threshold alone takes every pixel
    (and every face would count as crossed); with the noise floor the masks stay those of the flame."""
    from dataclasses import replace

    import torch

    from nerif.masks.backprojection import noise_level

    rms = float(scene.eps.norm(dim=-1).pow(2).mean().sqrt())
    sigma_n = 0.2 * rms / 3**0.5  # per component
    noisy = replace(scene, eps=scene.eps + sigma_n * torch.randn(scene.eps.shape, generator=torch.Generator().manual_seed(0)))
    img = noisy.view_image(0, noisy.eps[noisy.view_slice(0)].numpy(), np.nan)
    assert noise_level(img) == pytest.approx(sigma_n, rel=0.25)  # coarse pixels: some curvature of the flame too
    clean = MASKS.build({"name": "3d"}, scene=scene)
    masks = MASKS.build({"name": "3d"}, scene=noisy)
    flame = scene.truth_T - scene.ambient.T0 > 100.0
    assert masks.volume[flame].all() and masks.volume.sum() < 1.5 * clean.volume.sum()
    assert ambient_faces("auto", noisy, masks, 0.1, ["x"]) == (list(FACES), [])


@pytest.mark.slow
@pytest.mark.parametrize("mask", ["3d", "2d"])
def test_a_flame_the_box_cuts_on_a_face_the_rays_cross_reconstructs_with_the_3d_mask(mask):
    """A blob centred 6 mm inside the +z face (which the rays cross), perpendicular-only data, 400 iterations.
    Measured (seed 0): mask=3d 18.6 K, mask=2d 22.7 K, the ambient field 68.7 K; before the notch fill and the
    automatic faces, a hull cut at a crossed face drove Phantom 5 to 188 K. The bound, 0.36 of the ambient
    field's error, is one both masks meet."""
    cfg = tiny_config("data.sensing=perpendicular", "phantom.centre_mm=[0.0,0.0,18.0]", "phantom.width_mm=8.0",
                      "rig.binning=20", "train.iterations=400", "train.eval_every=400", f"mask={mask}")
    scene = DATASETS.build(group(cfg, "data"))
    tr = solver(cfg, scene, MASKS.build(group(cfg, "mask"), scene=scene))
    tr.fit(checkpoint_every=10**9, progress=False)
    assert "+z" in tr.report["flame_crosses_faces"] and tr.report["ambient_faces"] == ["-z"]
    ambient = float(np.sqrt(((scene.truth_T - scene.ambient.T0) ** 2).mean()))
    assert tr.history[-1]["temperature_rmse_K"] < 0.36 * ambient, (tr.history[-1]["temperature_rmse_K"], ambient)


@pytest.mark.slow
def test_the_hull_keeps_a_cut_flame_on_fine_images():
    """Phantom 5 (hot on its y and z faces) on 2 x 2 binned images (3.5 px/mm at the probe): a dilation of 2 px
    leaves a strip of short, barely deflected rays along the box image's cut edges that joins the flame's open
    core to two sides, so the hole is not filled and the hull carves a third of the flame away (measured: 68 %
    kept). The default dilation, at least 2.3 mm at the probe (8 px here, 2 px on the default 8 x 8 binned
    images), keeps all of it."""
    # the default scene (Phantom 5 on 2 mm voxels, 12 views) on finer images, its deflections by a step of a voxel
    # (the masks' share kept as with half of it: 0.680 against 0.679; half the rendering's time)
    cfg = compose(["rig.binning=2", "data.sensing=perpendicular", "data.render_supersample=1", "data.render_step_mm=2.0",
                   "data.cache_dir=null", "mask=3d"])
    fine = DATASETS.build(group(cfg, "data"))
    flame = fine.truth_T - fine.ambient.T0 > 10.0
    kept = {r: (MASKS.build({**group(cfg, "mask"), "radius_mm": r}, scene=fine).volume & flame).sum() / flame.sum()
            for r in (0.0, cfg.mask.radius_mm)}
    assert kept[cfg.mask.radius_mm] == 1.0
    assert kept[0.0] < 0.8


def test_a_view_whose_pixels_are_unknown_carves_nothing(scene):
    """``unknown`` pixels (no usable measurement) count as inside a view's mask: a view with an empty mask but every
    pixel unknown leaves the visual hull of the other views as it is, while the same empty mask measured carves
    everything."""
    images = [m.astype(bool) for m in MASKS.build({"name": "2d"}, scene=scene).images]
    empty = [np.zeros_like(images[0])] + images[1:]
    unknown = [np.ones_like(images[0])] + [None] * (len(images) - 1)
    others = back_project(scene.box, scene.cameras[1:], images[1:])
    assert others.any()
    np.testing.assert_array_equal(back_project(scene.box, scene.cameras, empty, unknown=unknown), others)
    assert not back_project(scene.box, scene.cameras, empty).any()
