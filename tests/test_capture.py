"""Capture folders: written from a synthetic scene, read back through optical flow, trained with a held-out
view; every bad folder gets one clear error before the flow runs."""
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from tests.helpers import SMALL, tiny_config
from nerif.app import run
from nerif.data import DATASETS
from nerif.data.capture import capture
from nerif.data.capture_images import capture_files
from nerif.data.rig_file import RIG_FILE, read_rig
from nerif.write_capture import write_capture
from omegaconf import OmegaConf

FLOW = {"name": "farneback"}


def test_capture_reads_back_the_scene(written):
    root, scene, _ = written
    rig = yaml.safe_load((root / RIG_FILE).read_text())
    assert rig["views"]["angles_deg"] == pytest.approx([0, 27.5, 55, 82.5, 110, 137.5, 165])
    cap = capture(str(root), FLOW, binning=8)
    assert cap.n_views == 6 and cap.heldout.n_views == 1  # the last view held out
    assert cap.sigma_prior == pytest.approx((-1.05, 0.05))  # from temperature_range_K = [T0, T_max]
    # training rays: the same pixels as the synthetic scene's first six views, deflections from the 8-bit images
    n = int(scene.view_start[6])
    assert torch.equal(cap.pixel, scene.pixel[:n]) and torch.allclose(cap.dirs, scene.dirs[:n])
    ref = scene.eps[:n]
    assert float((cap.eps - ref).norm(dim=-1).pow(2).mean().sqrt()) < 0.1 * float(ref.norm(dim=-1).pow(2).mean().sqrt())
    # and against the truth (thin-ray deflections perpendicular to the rays): within the blur of the f/32 aperture
    cfg = tiny_config(*SMALL, "data.sensing=perpendicular")
    ideal = DATASETS.build(OmegaConf.to_container(cfg.data, resolve=True), device="cpu").eps[:n]
    rel = float((cap.eps - ideal).norm(dim=-1).pow(2).mean().sqrt() / ideal.norm(dim=-1).pow(2).mean().sqrt())
    assert rel < 0.5, rel
    # the deflections map back onto the displacements they were measured as, through the full sensor's pixels
    u = cap.to_displacement(cap.eps)
    assert float((u - cap.displacements).abs().max()) < 1e-4 * float(cap.displacements.abs().max())


@pytest.mark.parametrize("mask", ["3d", "2d"])  # 3d: the default
def test_train_on_a_capture_with_a_held_out_view(written, tmp_path, mask):
    root, _, _ = written
    figures = mask == "3d"  # the held-out view's figure drawn in one run, and none where figures=false
    cfg = tiny_config("data=capture", f"data.root={root}", "data.binning=8", f"mask={mask}", "train.iterations=150",
                      "train.eval_every=50", f"figures={figures}", synthetic=False)
    m = run(cfg, tmp_path)
    h = capture(str(root), FLOW, binning=8).heldout
    u_obs = h.displacements  # as measured
    rms_obs = float(u_obs.norm(dim=-1).pow(2).mean().sqrt())
    assert m["heldout_displacement_rmse_px"] < 0.6 * rms_obs, (m["heldout_displacement_rmse_px"], rms_obs)
    assert np.isfinite(m["heldout_psnr_db"]) and np.isfinite(m["heldout_displacement_psnr_db"])
    assert "temperature_rmse_K" not in m  # no ground truth, no temperature error claimed
    assert m["T_peak_K"] > 296.15 and len(m["T_peak_position_mm"]) == 3 and "T_peak_true_K" not in m
    unknown = {k for k, u in m["units"].items() if u == "?"}
    assert not unknown and m["units"]["heldout_displacement_rmse_px"] == "px", unknown  # issue 50: every key's unit
    assert m["ambient_faces"]  # auto never leaves the level unpinned (here the flow's smoothing inflates the masks)
    number = int(h.cameras[0].name.split()[1])  # "camera 04 (160.0 deg)": the figure is named by its camera
    drawn = [p.name for p in (tmp_path / "heldout").iterdir()] if figures else []
    assert drawn == ([f"camera{number:02d}.png"] if figures else []) and (tmp_path / "heldout").exists() == figures
    assert (tmp_path / "reconstruction.npz").is_file()


def _variant(written, tmp_path, edit_rig=None, edit_files=None):
    """A copy of the written capture, with its rig file and images edited."""
    root = written[0]
    dst = tmp_path / "cap"
    shutil.copytree(root, dst)
    rig = yaml.safe_load((dst / RIG_FILE).read_text())
    if edit_rig:
        edit_rig(rig)
    (dst / RIG_FILE).write_text(yaml.safe_dump(rig))
    if edit_files:
        edit_files(dst)
    return str(dst)


def _write(path, img):
    import cv2
    cv2.imwrite(str(path), img)


def _swap(a, b):
    shutil.move(a, a.with_suffix(".tmp"))
    shutil.move(b, a)
    shutil.move(a.with_suffix(".tmp"), b)


def _read(path):
    import cv2
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)


@pytest.mark.parametrize("edit_rig, edit_files, error, message", [
    (None, lambda d: (d / "distorted_03.png").unlink(), FileNotFoundError, "view 3 image 'distorted_03.png'"),
    (None, lambda d: shutil.copy(d / "distorted_03.png", d / "distorted_07.png"), ValueError,
     "distorted_07.png that rig.yaml does not list"),
    (lambda r: r["views"]["angles_deg"].pop(), None, ValueError, "6 angles but views.images lists 7"),
    (None, lambda d: _write(d / "distorted_02.png", _read(d / "distorted_02.png")[:-8]), ValueError,
     "distorted_02.png is 240 x 312 px but the rig's sensor_px \\(a calibration's image_size\\) is 240 x 320"),
    (None, lambda d: _write(d / "reference_01.png", _read(d / "reference_01.png").astype(np.uint16) * 257),
     ValueError, "same bit depth"),
    (None, lambda d: [_write(d / f"distorted_{k:02d}.png", _read(d / f"distorted_{k:02d}.png").astype(np.uint16) * 257)
                      for k in range(7)], ValueError, "same bit depth"),  # issue 28: 16-bit images, 8-bit references
    (None, lambda d: _write(d / "distorted_00.png", np.repeat(_read(d / "distorted_00.png")[..., None], 3, -1)),
     ValueError, "colour image"),
    (lambda r: r.update(roi_px=[200, 0, 100, 320]), None, ValueError, "roi_px .* is not inside"),
    (lambda r: r.update(roi_px=[0, 0, 16, 16]), None, ValueError, "no pixel of roi_px .* sees the probe box"),
    (lambda r: r.update(version=4), None, ValueError, "has version 4; this nerif reads versions 1, 2 and 3"),
    (lambda r: r.update(version=3), None, ValueError, "version 3 needs either .calibration. .* or a .cameras. list"),
    (lambda r: r["camera"].pop("pitch_um"), None, ValueError, "lacks 'pitch_um'"),
    (lambda r: r.update(temperature_range_K=[2000, 300]), None, ValueError, "two increasing positive temperatures"),
    (lambda r: r["camera"].update(camera_to_background_mm=500), None, ValueError,
     "camera.camera_to_background_mm = 500 must exceed camera.camera_to_centre_mm"),
    (lambda r: r["camera"].update(focal_mm=-105), None, ValueError, "camera.focal_mm = -105 must be a positive number"),
    (lambda r: r["camera"].update(pitch_um=0.02), None, ValueError, "camera.pitch_um = 0.02 is outside what cameras have .*0.02 mm is 20 um"),
    (None, lambda d: (d / "rig.yaml").write_text("format: nerif-capture\nversion: [1\n"), ValueError,
     "rig.yaml is not valid YAML \\(line 3\\)"),
    (lambda r: r["camera"].update(focal_mm="abc"), None, ValueError, "camera.focal_mm = 'abc' must be a positive"),
    (lambda r: r.update(occluders=["mask.png"]), None, ValueError, "occluders must list one mask image per view \\(7"),
    # issue 38: the rig file against its schema, each message naming the key
    (lambda r: r.update(held_out=[3]), None, ValueError, "unknown key 'held_out' .*did you mean 'heldout'"),
    (lambda r: r.update(Tmax=2500), None, ValueError, "unknown key 'Tmax' .*did you mean 'T_max'"),
    (lambda r: r["camera"].update(pitch_mm=0.02), None, ValueError, "unknown key 'camera.pitch_mm' .*'camera.pitch_um'"),
    (lambda r: r.update(calibration="c.yml"), None, ValueError, "unknown key 'calibration' for a version-2 rig file: the keys are"),
    (lambda r: r["ambient"].update(T0=23.0), None, ValueError, "ambient.T0 = 23.0 is not a temperature in kelvin"),
    (lambda r: r["camera"].update(sensor_px=r["camera"]["sensor_px"][::-1]), None, ValueError,
     "distorted_00.png is 240 x 320 px but the rig's sensor_px .* is 320 x 240: sensor_px is \\(width, height\\), swap"),
    (None, lambda d: [_write(p, _read(p)[::2, ::2]) for p in d.glob("*.png")], ValueError,
     "is 120 x 160 px .*binned 2 x 2 in the camera\\? Then give the images' size as sensor_px"),
    (lambda r: r["camera"].update(focal_mm=0.105), None, ValueError,
     "camera.focal_mm = 0.105 is outside what cameras have .*a focal length in metres\\? 0.105 m is 105 mm"),
    (lambda r: r["camera"].update(camera_to_centre_mm=0.8, camera_to_background_mm=1.6), None, ValueError,
     "camera.camera_to_centre_mm = 0.8 .*a distance in metres"),
    (lambda r: r.update(heldout=3), None, ValueError, "heldout = 3 must be a list of whole numbers"),
    (lambda r: r["camera"].update(f_number=3200), None, ValueError, "camera.f_number = 3200 is outside what cameras have"),
    (lambda r: r["views"]["images"].__setitem__(0, 5), None, ValueError,
     "views.images\\[0\\] = 5 must be a file name, or a list of file names \\(the exposures of one state\\)"),
    (lambda r: r["views"]["images"].__setitem__(2, ["distorted_02.png", "distorted_02b.png"]), None, FileNotFoundError,
     "view 2 image 'distorted_02b.png', which does not exist"),
    (lambda r: r["ambient"].update(n0=1.27), None, ValueError, "ambient.n0 = 1.27 must be a gas's refractive index"),
    (lambda r: r.update(roi_px=[0, 0, 240]), None, ValueError, "roi_px \\(x, y, width, height\\) = \\[0, 0, 240\\] must "
     "be 4 whole numbers"),
    (lambda r: r.update(heldout=6), None, ValueError, "heldout = 6 must be a list of whole numbers"),
    (lambda r: r["views"].update(angles_deg="0 27.5 55 82.5 110 137.5 165"), None, ValueError,
     "views.angles_deg = '0 27.5 .*' must be a list of numbers"),
    (lambda r: r["probe"].update(shape="16x16x16"), None, ValueError, "probe.shape = '16x16x16' must be 3 whole numbers"),
    (lambda r: r.update(T_max="2000 K"), None, ValueError, "T_max = '2000 K' must be a positive number"),
    (lambda r: r.update(temperature_range_K=300), None, ValueError, "temperature_range_K 300 must be two increasing"),
    (lambda r: r.update(occluders=["mask.png"] + [None] * 6), None, FileNotFoundError,
     "view 0's occluder mask 'mask.png', which does not exist"),
])
def test_bad_capture_folders(written, tmp_path, monkeypatch, edit_rig, edit_files, error, message):
    import nerif.data.capture as cap_mod

    def no_flow(*a, **k):
        raise AssertionError("the flow ran on a bad capture")

    monkeypatch.setattr(cap_mod.FLOW, "build", no_flow)
    with pytest.raises(error, match=message):
        capture(_variant(written, tmp_path, edit_rig, edit_files), FLOW, binning=8)


def test_swapped_reference_and_distorted_images_are_refused_before_training(written, tmp_path):
    """Issue 28: swapped images gave a field pinned at the cold bound, 419 K off, without a word."""
    from nerif.data.diagnostics import hot_evidence

    def swap(rig):
        v = rig["views"]
        refs = v["references"] if isinstance(v["references"], list) else [v["references"]] * len(v["images"])
        v["images"], v["references"] = refs, v["images"]

    assert hot_evidence(capture(written[0], FLOW, binning=8)) < -0.3
    root = _variant(written, tmp_path, swap)
    assert hot_evidence(capture(root, FLOW, binning=8)) > 0.3
    cfg = tiny_config("data=capture", f"data.root={root}", "data.binning=8", synthetic=False)
    with pytest.raises(ValueError, match="the reference and distorted images look swapped; swap them"):
        run(cfg, tmp_path / "run")
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_no_held_out_view_trains_on_every_view_and_a_rig_setting_is_refused(written, tmp_path):
    """Issue 28: data.heldout=[] failed after the flow; rig.binning=4 with a capture was ignored without a word."""
    from tests.helpers import nerif_here

    every = capture(str(written[0]), FLOW, binning=8, heldout=[])
    assert every.n_views == 7 and every.heldout is None
    r = nerif_here("data=capture", f"data.root={written[0]}", "rig.binning=4", f"hydra.run.dir={tmp_path}")
    assert r.returncode == 2 and "Traceback" not in r.stderr + r.stdout
    assert "rig.binning=4: rig.* describes the synthetic rig; data=capture takes its cameras from its own files (the " \
           "binning of recorded data is data.binning)" in r.stderr + r.stdout


def test_one_shared_reference(written, tmp_path):
    def share(rig):
        rig["views"]["references"] = "reference_00.png"

    def drop(d):
        for k in range(1, 7):
            (d / f"reference_{k:02d}.png").unlink()

    root = _variant(written, tmp_path, share, drop)
    distorted, references = capture_files(read_rig(Path(root)))
    assert len(distorted) == 7 and {p.name for files in references for p in files} == {"reference_00.png"}


SERIES = [o for o in SMALL if not o.startswith("phantom")] + [
    "phantom=flicker", "phantom.shape=[16,16,16]", "phantom.voxel_mm=2.0", "phantom.lift_mm=-14",
    "phantom.base_radius_mm=5", "phantom.flame_length_mm=24", "phantom.thickness_mm=2", "phantom.wavelength_mm=12",
    "phantom.amplitude=0.6", "data.frames=3", "data.frame_rate_hz=24", "data.render_supersample=1", "data.cache_dir=null"]


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """A capture of 3 frames of a flickering flame at 24 frames/s (frame 1: half a period after frame 0)."""
    from nerif.sequence import frames_of

    data = OmegaConf.to_container(tiny_config(*SERIES, synthetic=False).data, resolve=True)
    frames = frames_of(data)
    scenes = [DATASETS.build(data, frame=f.index) for f in frames]
    root = write_capture(iter(scenes), tmp_path_factory.mktemp("series"), times=[f.time_s for f in frames])
    return root, scenes


def test_a_series_reads_back_frame_by_frame(series):
    """Version 2: the frames listed with their times; each frame reads back as its own state: closer to the
    thin-ray deflections of its own time than to those of the other state."""
    from nerif.data.capture import capture_frames
    from nerif.data.frames import Frame

    root, scenes = series
    rig = read_rig(root)
    assert rig.version == 2 and len(rig.frames) == 3
    assert "images" not in yaml.safe_load((root / RIG_FILE).read_text())["views"]
    assert rig.frames[1].images[0] == "frame_0001/distorted_00.png"
    assert capture_frames(str(root)) == [Frame(0, 0.0), Frame(1, pytest.approx(1 / 24)), Frame(2, pytest.approx(2 / 24))]
    assert capture_frames(str(root), frames=[1, 2])[0].index == 1
    from nerif.sequence import frames_of

    picked = tiny_config("data=capture", f"data.root={root}", "data.frames=[0,2]", synthetic=False)  # as users write it
    assert [f.index for f in frames_of(OmegaConf.to_container(picked.data, resolve=True))] == [0, 2]
    n = int(scenes[0].view_start[6])
    caps = [capture(str(root), FLOW, binning=8, frame=k) for k in range(2)]
    truth = [s.eps[:n] for s in scenes[:2]]
    for k in range(2):
        own, other = ((caps[k].eps - truth[j]).norm(dim=-1).pow(2).mean().sqrt() for j in (k, 1 - k))
        assert own < 0.7 * other, (k, float(own), float(other))


def test_a_one_frame_capture_of_version_1_still_reads(written, tmp_path):
    root = _variant(written, tmp_path, lambda r: r.update(version=1))
    assert capture(root, FLOW, binning=8).n_views == 6


def _series_variant(series, tmp_path, edit_rig=None, edit_files=None):
    return _variant((series[0],), tmp_path, edit_rig, edit_files)


def _drop_last(rig):
    rig["frames"][2]["images"].pop()


@pytest.mark.parametrize("edit_rig, edit_files, message", [
    (None, lambda d: (d / "frame_0002" / "distorted_04.png").unlink(), "frame 2 view 4 image 'frame_0002/distorted_04.png'"),
    (_drop_last, None, "frame 2 lists 6 images for 7 views"),
    (None, lambda d: _write(d / "frame_0001" / "distorted_03.png", _read(d / "frame_0001" / "distorted_03.png")[8:]),
     "distorted_03.png is 240 x 312 px but the rig's sensor_px \\(a calibration's image_size\\) is 240 x 320"),
    (None, lambda d: shutil.copy(d / "frame_0001" / "distorted_03.png", d / "frame_0001" / "distorted_09.png"),
     r"frame_0001/distorted_09.png that rig.yaml does not list"),
    (lambda r: r["frames"][2].update(time_s=0.01), None, "frame 2 has time_s 0.01, not after frame 1's"),
    (lambda r: r["views"].update(images=r["frames"][0]["images"]), None, "either as views.images .* not both"),
    (lambda r: r["frames"][1].pop("time_s"), None, "frame 1 lacks 'time_s'"),
    (lambda r: r["frames"][1].update(time_s="abc"), None, "frame 1's time_s = 'abc' must be a number of seconds"),
])
def test_bad_series_folders_are_one_sentence_before_any_flow(series, tmp_path, monkeypatch, edit_rig, edit_files,
                                                              message):
    """Every frame of a series is checked before the first frame's flow runs, each error naming the file: a run
    of the whole series (as ``python -m nerif`` starts it) fails before any flow (issue 36: the test called only
    the check, which never runs the flow, so its guard could not fail)."""
    import nerif.data.capture as cap_mod

    def no_flow(*a, **k):
        raise AssertionError("the flow ran on a bad capture")

    monkeypatch.setattr(cap_mod.FLOW, "build", no_flow)
    root = _series_variant(series, tmp_path, edit_rig, edit_files)
    with pytest.raises((ValueError, FileNotFoundError), match=message):
        run(tiny_config("data=capture", f"data.root={root}", "data.binning=8", synthetic=False), tmp_path / "run")


def test_a_series_capture_reconstructs_every_frame_warm_started(series, tmp_path):
    root = series[0]
    cfg = tiny_config("data=capture", f"data.root={root}", "data.binning=8", "train.iterations=40",
                      "sequence.iterations=10", "uncertainty=auto", synthetic=False)
    m = run(cfg, tmp_path)
    # each frame fits the flow for its iterations, then the images for half as many more (data_term.image_iterations)
    assert [(r["frame"], r["warm_start"], r["iterations"]) for r in m["frames"]] == [(0, False, 60), (1, True, 15),
                                                                                   (2, True, 15)]
    assert all(r["heldout_displacement_rmse_px"] > 0 for r in m["frames"]) and m["temperature_rmse_K"] is None  # no truth
    kept = [r["data_term_kept"] for r in m["frames"]]  # each frame's held-out choice, and how often the series made it
    assert set(kept) <= {"images", "flow"} and m["data_term_kept"].endswith(f"in {kept.count(max(kept))} of 3 frames")
    assert (tmp_path / "sequence.pvd").read_text().count("reconstruction.vti") == 3
    lo, hi = m["T_peak_interval_K"]  # issue 59: each frame's interval (a held-out view each), their ends' means
    assert lo <= m["T_peak_K"] <= hi


def test_optional_rig_keys_left_null_take_their_defaults(written, tmp_path):
    """Issue 36: ``T_max: null`` or ``heldout: null`` in rig.yaml ended in a TypeError traceback. Null is absent:
    T_max 2000 K, the last view held out."""
    root, _, _ = written
    rig = yaml.safe_load((root / RIG_FILE).read_text())
    for f in root.iterdir():
        if f.suffix == ".png":
            (tmp_path / f.name).symlink_to(f)
    rig.update(T_max=None, heldout=None, temperature_range_K=None)
    (tmp_path / RIG_FILE).write_text(yaml.safe_dump(rig))
    cap = capture(str(tmp_path), FLOW, binning=8)
    assert cap.ambient.T_max == 2000.0
    assert cap.n_views == 6 and cap.heldout.n_views == 1 and cap.heldout.cameras[0].name.startswith("camera 06 ")


def test_a_patch_without_estimates_is_unknown_and_carves_no_flame(written, monkeypatch):
    """Issue 36: a pixel without a usable measurement had no ray, and the visual hull took it as ambient: a patch of
    NaN flow over the flame in one view carved the flame away. It is unknown now: no ray, and the hull keeps every
    voxel it keeps without the patch."""
    from nerif.masks import MASKS
    from nerif.sensing.flow import FLOW as FLOWS

    root = written[0]
    clean = capture(str(root), FLOW, binning=8)
    build, calls = FLOWS.build, []

    def holed(cfg, **images):
        u = build(cfg, **images)
        if images["reference"].shape != (320, 240):  # the flow's check of its settings on a test pair
            return u
        calls.append(images["reference"])
        if calls[-1] is calls[0]:  # the first view (each flow of it): rows 120-200, columns 80-160 of its 240 x 320
            u[120:200, 80:160] = np.nan  # image, the flame's centre
        return u

    monkeypatch.setattr(FLOWS, "build", holed)
    cap = capture(str(root), FLOW, binning=8)
    patch = np.zeros((40, 30), bool)
    patch[15:25, 10:20] = True
    np.testing.assert_array_equal(cap.valid_images[0], ~patch)
    assert int(cap.view_counts()[0]) < int(clean.view_counts()[0]) and cap.eps.isfinite().all()
    hull_clean, hull = (MASKS.build({"name": "3d"}, scene=s).volume for s in (clean, cap))
    flame = written[1].truth_T - written[1].ambient.T0 > 50.0
    assert flame.any() and hull_clean[flame].all() and hull[flame].all()
    assert hull[hull_clean].all()


def test_an_occluder_mask_in_the_rig_file_is_unknown_and_carves_no_flame(written, tmp_path):
    """Issue 37: ``occluders`` in rig.yaml, one mask per view (null: none): a mask over the flame's centre in the first
    view (a probe held in front of the background) leaves those pixels unknown, no ray and no carving, counted as
    occluded; the other views are as without it."""
    from nerif.masks import MASKS

    def add_mask(d):
        mask = np.zeros((320, 240), np.uint8)
        mask[120:200, 80:160] = 255
        _write(d / "probe_mask.png", mask)

    root = _variant(written, tmp_path, lambda r: r.update(occluders=["probe_mask.png"] + [None] * 6), add_mask)
    clean, cap = capture(str(written[0]), FLOW, binning=8), capture(root, FLOW, binning=8)
    patch = np.zeros((40, 30), bool)
    patch[15:25, 10:20] = True
    assert not cap.valid_images[0][patch].any()
    np.testing.assert_array_equal(cap.valid_images[0] | patch, clean.valid_images[0] | patch)
    for v in range(1, cap.n_views):
        np.testing.assert_array_equal(cap.valid_images[v], clean.valid_images[v])
    occluded = [f.occluded for f in cap.findings]  # per view, a share of the ray grid
    assert occluded[0] == pytest.approx(patch.mean()) and occluded[1] == 0.0
    hull_clean, hull = (MASKS.build({"name": "3d"}, scene=s).volume for s in (clean, cap))
    flame = written[1].truth_T - written[1].ambient.T0 > 50.0
    assert flame.any() and hull[flame].all() and hull[hull_clean].all()


def test_a_series_decodes_each_image_once_and_builds_its_rays_once(series, monkeypatch):
    """Issue 36: every image of a series was decoded twice (once to check it, once to measure it), the shared
    references once per frame, and the cameras and their rays were built again for every frame."""
    import nerif.data.capture as cap_mod
    import nerif.data.capture_images as images_mod
    from nerif.data.capture import capture_frames

    root = series[0]
    decoded, built = [], []
    imread, rays_in_box = images_mod.cv2.imread, cap_mod.rays_in_box
    monkeypatch.setattr(images_mod.cv2, "imread", lambda p, *a: decoded.append(p) or imread(p, *a))
    monkeypatch.setattr(cap_mod, "rays_in_box", lambda *a: built.append(1) or rays_in_box(*a))
    monkeypatch.setattr(cap_mod, "_GEOMETRY", {})
    monkeypatch.setattr(cap_mod, "_REFERENCES", {})
    frames = capture_frames(str(root), frames=None)
    scenes = [capture(str(root), FLOW, binning=8, frame=f.index) for f in frames]
    n = scenes[0].n_views + scenes[0].heldout.n_views
    assert len(decoded) == len(set(decoded)) == 3 * n + n  # every frame's images, and the references once
    assert len(built) == 1


def test_jpeg_images_are_read_with_a_warning_that_names_the_lossy_format(written, tmp_path, caplog):
    """Issue 38: JPEG at quality 50 cost the shared capture's sigma error 0.22 against 0.125, without a word."""
    from PIL import Image

    def to_jpeg(rig):
        rig["views"]["images"] = [f.replace(".png", ".jpg") for f in rig["views"]["images"]]

    def convert(d):
        for f in sorted(d.glob("distorted_*.png")):
            Image.open(f).save(f.with_suffix(".jpg"), quality=50)
            f.unlink()

    with caplog.at_level("WARNING"):
        capture(_variant(written, tmp_path, to_jpeg, convert), FLOW, binning=8)
    assert "7 of the capture's 14 images are JPEG (distorted_00.jpg, ...), a lossy format" in caplog.text


def test_the_noise_of_k_exposures_averaged_falls_as_one_over_sqrt_k():
    """Issue 39: the noise of the mean of K exposures, estimated from their spread, against the noise put in."""
    from nerif.data.capture_images import exposure_noise

    rng = np.random.default_rng(0)
    image = rng.random((120, 160)).astype(np.float32)
    sigma = 0.02
    noise = {k: exposure_noise(image + rng.normal(0, sigma, (k, 120, 160)).astype(np.float32)) for k in (1, 2, 8, 32)}
    assert noise[1] is None
    for k in (2, 8, 32):
        assert noise[k] == pytest.approx(sigma / np.sqrt(k), rel=0.03), (k, noise[k])
    assert noise[8] / noise[2] == pytest.approx(0.5, rel=0.04)


def test_several_exposures_per_view_are_averaged(written, tmp_path):
    """Issue 39: a view's image may be a list of files in rig.yaml, the exposures of one state: they are averaged,
    their noise is reported per view, and the displacements come nearer the truth than from one exposure."""
    rng = np.random.default_rng(1)
    k, sigma = 4, 0.04

    def noisy(rig):
        rig["views"]["images"] = [[f"distorted_{v:02d}_{e}.png" for e in range(k)] for v in range(7)]

    def expose(d):  # images lifted to mid-grey (the noise unclipped), then K noisy exposures of each distorted one
        for v in range(7):
            _write(d / f"reference_{v:02d}.png", np.rint(64 + 0.6 * _read(d / f"reference_{v:02d}.png")).astype(np.uint8))
            clean = 64 + 0.6 * _read(d / f"distorted_{v:02d}.png").astype(np.float32)
            for e in range(k):
                _write(d / f"distorted_{v:02d}_{e}.png",
                       np.clip(np.rint(clean + rng.normal(0, 255 * sigma, clean.shape)), 0, 255).astype(np.uint8))
            (d / f"distorted_{v:02d}.png").unlink()

    root = _variant(written, tmp_path / "k", noisy, lambda d: expose(d))
    many = capture(root, FLOW, binning=8)
    assert many.findings[0].exposures == [k, 1]
    assert all(n == pytest.approx(sigma / np.sqrt(k), rel=0.1) for n in [f.image_noise for f in many.findings]), \
        [f.image_noise for f in many.findings]
    assert many.findings[0].reference_noise is None

    def single(rig):
        rig["views"]["images"] = [f"distorted_{v:02d}_0.png" for v in range(7)]

    def one(d):
        expose(d)
        for v in range(7):
            for e in range(1, k):
                (d / f"distorted_{v:02d}_{e}.png").unlink()

    once = capture(_variant(written, tmp_path / "one", single, one), FLOW, binning=8)
    truth = written[1].eps[: int(written[1].view_start[6])]

    def error(scene):
        return float((scene.eps - truth).norm(dim=-1).pow(2).mean().sqrt())

    assert once.findings[0].image_noise is None
    assert error(many) < 0.65 * error(once), (error(many), error(once))  # measured 0.50x: 1 / sqrt(4)


def test_a_pixel_clipped_in_one_exposure_stays_clipped_in_the_mean(tmp_path):
    """Averaging K exposures must not hide a clipped pixel below full scale, where the saturation step looks."""
    from nerif.data.capture_images import read_exposures

    a = np.full((8, 10), 100, np.uint8)
    b = a.copy()
    b[3, 4] = 255
    for name, img in (("a.png", a), ("b.png", b)):
        _write(tmp_path / name, img)
    (mean,), (noise,) = read_exposures([(tmp_path / "a.png", tmp_path / "b.png")], (10, 8))
    assert mean[3, 4] == 1.0 and mean[0, 0] == pytest.approx(100 / 255) and noise > 0


def test_a_capture_run_reads_its_rig_file_once_and_again_only_once_it_changed(written, tmp_path, monkeypatch):
    """Issue 47: one run opened rig.yaml five times (memory estimate, frames, scene). It is now read once a process
    while it and its calibration file stay as they were; a rewritten rig file is read again, not served stale."""
    import nerif.data.rig_file as rig_file

    root = Path(_variant(written, tmp_path))
    reads = []
    real = rig_file._read_rig_file
    monkeypatch.setattr(rig_file, "_read_rig_file", lambda path: reads.append(path) or real(path))
    run(tiny_config("data=capture", f"data.root={root}", "data.binning=8", "train.iterations=2", synthetic=False),
        tmp_path / "run")
    assert len(reads) == 1
    t_max = rig_file.read_rig(root).ambient.T_max
    assert len(reads) == 1
    rig = yaml.safe_load((root / RIG_FILE).read_text())
    rig["T_max"] = t_max + 100.0
    (root / RIG_FILE).write_text(yaml.safe_dump(rig))
    assert rig_file.read_rig(root).ambient.T_max == t_max + 100.0 and len(reads) == 2


def test_a_second_measurement_of_the_same_images_is_read_back_and_any_change_measures_again(written, tmp_path, caplog, monkeypatch):
    """Issue 47: every run of a capture ran the optical flow of every view again. Each view's measurement is now
    kept under ``cache_dir``, keyed by its images' values, masks, grid and settings: the same capture gives the same
    scene without the flow (the log and each view's ``from_cache`` say so); other settings or another image do not."""
    import logging

    import nerif.sensing.measurement as measurement

    root = Path(_variant(written, tmp_path))
    cache = tmp_path / "cache"
    first = capture(root, FLOW, binning=8, cache_dir=cache)
    flows = []
    real = measurement.estimate
    monkeypatch.setattr(measurement, "estimate", lambda *a, **k: flows.append(1) or real(*a, **k))
    with caplog.at_level(logging.INFO):
        again = capture(root, FLOW, binning=8, cache_dir=cache)
    assert not flows and "read from the cache" in caplog.text
    assert torch.equal(first.eps, again.eps) and np.array_equal(first.valid_images[0], again.valid_images[0])
    assert not any([f.from_cache for f in first.findings]) and all([f.from_cache for f in again.findings])
    assert ([replace(f, from_cache=None) for f in first.findings] ==
            [replace(f, from_cache=None) for f in again.findings])
    capture(root, {**FLOW, "normalise_px": 4.0}, binning=8, cache_dir=cache)  # another setting
    assert len(flows) == first.n_views + 1  # every view, and the held-out one
    image = root / "distorted_00.png"
    _write(image, 255 - _read(image))
    flows.clear()
    capture(root, FLOW, binning=8, cache_dir=cache)
    assert len(flows) == 1  # that view alone


def test_a_measurements_picture_is_drawn_once_and_copied_by_the_next_run(written, tmp_path, monkeypatch):
    """Issue 47: the pictures of a measurement (most of a second run's set-up once the measurement is cached) are
    kept with it, keyed by what they show: the same measurement copies them, a changed view draws its own again."""
    from dataclasses import replace

    import nerif.io.outputs as outputs
    from nerif.sensing.measurement import CAUSES

    scene = capture(str(written[0]), FLOW, binning=8)
    drawn = []
    original = outputs.measured_figure
    monkeypatch.setattr(outputs, "measured_figure", lambda *a, **k: drawn.append(a[-1]) or original(*a, **k))
    views = scene.n_views + scene.heldout.n_views
    outputs.write_sensing(scene, tmp_path / "a", CAUSES, tmp_path / "cache")
    outputs.write_sensing(scene, tmp_path / "b", CAUSES, tmp_path / "cache")
    assert len(drawn) == views
    for a in sorted((tmp_path / "a" / "sensing").iterdir()):
        assert a.read_bytes() == (tmp_path / "b" / "sensing" / a.name).read_bytes()
    left_out = scene.views[0].left_out.copy()
    left_out[0, 0] = 1  # one ray more left out in the first view
    changed = replace(scene, views=[replace(scene.views[0], left_out=left_out), *scene.views[1:]])
    outputs.write_sensing(changed, tmp_path / "c", CAUSES, tmp_path / "cache")
    assert len(drawn) == views + 1 and drawn[-1].startswith(scene.cameras[0].name)
