"""``python -m nerif.write_capture``: a capture folder whose rig file describes the cameras that made it."""
import numpy as np
import pytest
import yaml

from nerif.data.capture_images import capture_files
from nerif.data.rig_file import RIG_FILE, read_rig
from nerif.write_capture import main

SMALL = ["rig.width_px=240", "rig.height_px=320", "rig.binning=8", "rig.n_cameras=3", "rig.distance_mm=700",
         "rig.background_behind_mm=500", "rig.f_number=16", "phantom=gaussian_blob", "phantom.shape=[16,16,16]",
         "phantom.voxel_mm=2.0", "phantom.width_mm=6.0", "data.sensor.aperture_rays=4", "data.render_supersample=1",
         "data.cache_dir=null"]


def test_the_rig_file_describes_the_cameras_that_took_the_images(tmp_path, capsys):
    root = main([str(tmp_path / "cap"), *SMALL])
    assert f"python -m nerif data=capture data.root={root} data.truth={root / 'volume.npz'}" in capsys.readouterr().out
    rig = read_rig(root)
    # issue 50: the truth it was rendered from, as the shared captures hold it, read back as data.truth reads it
    from nerif.data.folders import read_truth
    from nerif.physics import Ambient

    truth = np.load(root / "volume.npz")
    T = read_truth(root / "volume.npz", rig.box)
    amb = Ambient(float(truth["T0"]), float(truth["n0"]), 2000.0)
    assert T.shape == (16, 16, 16) and abs(T.min() - amb.T0) < 1.0 and T.max() > 1000.0
    np.testing.assert_allclose(truth["sigma"], amb.sigma_from_temperature(T), rtol=1e-6)
    assert float(truth["delta_thre"]) == amb.delta_thre and float(truth["voxel_mm"]) == 2.0
    lens = rig.lens
    assert rig.sensor_px == (240, 320) and lens.focal_mm == 105.0 and lens.f_number == 16.0
    assert lens.pitch_um == pytest.approx(20.0)  # images on the full sensor
    assert lens.camera_to_centre_mm == pytest.approx(700.0) and lens.camera_to_background_mm == pytest.approx(1200.0)
    assert rig.angles_deg == pytest.approx([0.0, 82.5, 165.0]) and rig.heldout == (2,)
    assert rig.box.shape == (16, 16, 16) and rig.box.voxel_mm == 2.0
    distorted, references = capture_files(rig)
    assert len(distorted) == len(references) == 3
    assert yaml.safe_load((root / RIG_FILE).read_text())["T_max"] == 2000.0
    import cv2

    img = cv2.imread(str(distorted[0][0]), cv2.IMREAD_UNCHANGED)
    assert img.shape == (320, 240) and img.dtype == np.uint8 and img.std() > 30


def test_a_time_series_is_written_frame_by_frame(tmp_path, capsys):
    """``data.frames=2`` of a phantom that changes in time: one folder of images per frame, the rig file listing
    each with its time, one reference per view for all."""
    over = [o for o in SMALL if not o.startswith("phantom")] + [
        "phantom=flicker", "phantom.shape=[16,16,16]", "phantom.voxel_mm=2.0", "data.frames=2", "data.frame_rate_hz=24"]
    root = main([str(tmp_path / "series"), *over])
    assert "capture of 2 frames of 3 views" in capsys.readouterr().out
    rig = read_rig(root)
    first, second = (np.load(root / f"frame_{k:04d}" / "volume.npz")["T"] for k in (0, 1))
    assert first.shape == (16, 16, 16) and np.abs(first - second).max() > 0  # each frame's own truth
    assert [f.time_s for f in rig.frames] == pytest.approx([0.0, 1 / 24])
    assert rig.frames[1].images == tuple(f"frame_0001/distorted_{v:02d}.png" for v in range(3))
    d0, refs = capture_files(rig, 0)
    d1, refs1 = capture_files(rig, 1)
    assert refs == refs1 and all(p.is_file() for files in d0 + d1 for p in files)
    import cv2

    a, b = (cv2.imread(str(d[0][0]), cv2.IMREAD_UNCHANGED).astype(float) for d in (d0, d1))
    assert np.abs(a - b).max() > 0  # the flame moved between the frames


def test_an_existing_folder_or_a_file_is_refused_and_overwrite_replaces_it_whole(tmp_path, capsys):
    """Issue 28: writing into an earlier capture overwrote rig.yaml and some images and left the rest (the folder
    was then refused); onto a file, a FileExistsError traceback."""
    root = main([str(tmp_path / "cap"), *SMALL])
    before = {p.name: p.read_bytes() for p in root.iterdir()}
    (tmp_path / "file").write_text("x")
    for target, message in ((root, "is not empty: choose a new folder, or add --overwrite"),
                            (tmp_path / "file", "is a file: give the folder")):
        with pytest.raises(SystemExit) as e:
            main([str(target), *SMALL, "rig.n_cameras=2"])
        assert e.value.code == 2 and message in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in root.iterdir()} == before
    with pytest.raises(SystemExit):
        main([str(tmp_path / "typo"), *SMALL, "rig.n_camera=2"])
    assert "rig.n_camera: not a setting nerif knows (did you mean rig.n_cameras?)" in capsys.readouterr().err
    assert not (tmp_path / "typo").exists()
    main([str(root), "--overwrite", *SMALL, "rig.n_cameras=2"])  # issue 38: --overwrite anywhere on the line
    assert sorted(p.name for p in root.iterdir()) == ["distorted_00.png", "distorted_01.png", "reference_00.png",
                                                      "reference_01.png", RIG_FILE, "volume.npz"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cap", "file"]  # no staging folder left


def test_overwrite_keeps_a_link_and_refuses_the_folder_it_runs_in(tmp_path, capsys, monkeypatch):
    """Issue 38: ``write_capture . --overwrite`` printed "error: 16" after rendering (renaming the folder it ran
    in); through a link it replaced the link. The link is followed now (the capture is written where it points, the
    link kept) and the folder the command runs in, or one holding it, is refused before anything is rendered."""
    (tmp_path / "target").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "target")
    root = main([str(tmp_path / "link"), *SMALL])
    assert root == tmp_path / "target" and (tmp_path / "link").is_symlink()
    main([str(tmp_path / "link"), "--overwrite", *SMALL, "rig.n_cameras=2"])
    assert (tmp_path / "link").is_symlink() and read_rig(tmp_path / "link").n_views == 2
    capsys.readouterr()
    monkeypatch.chdir(tmp_path / "target")
    for target in (".", str(tmp_path)):
        with pytest.raises(SystemExit) as e:
            main([target, "--overwrite", *SMALL, "phantom.shape=[abc]"])  # refused before the config is read
        said = capsys.readouterr().err
        assert e.value.code == 2 and "is the folder this command runs in (or holds it)" in said, said
    assert read_rig(tmp_path / "target").n_views == 2


def test_a_dirty_capture_is_written_and_its_burner_read_back_as_occluded(tmp_path, capsys):
    """Issue 37: the realistic chain's burner, light and shake go into the written images; reading the folder back,
    the measurement stage finds the burner's share of each view (the chain's ``occluded_true``, from the geometry)
    as occluded, and the flame's light does not stop the capture."""
    from nerif.configs import compose, group
    from nerif.data import DATASETS
    from nerif.data.capture import capture

    dirt = ["data.sensor.burner_radius_mm=4", "data.sensor.luminosity=0.3", "data.sensor.shake_px=0.1"]
    root = main([str(tmp_path / "dirty"), *SMALL, *dirt])
    scene = capture(str(root), {"name": "farneback", "normalise_px": "auto"}, binning=8)
    found = [f.occluded for f in scene.findings + scene.heldout.findings]  # the held-out view is the last
    truth = DATASETS.build(group(compose(["data.sensing=realistic", *SMALL, *dirt]), "data"))
    true = truth.sensing.occluded_true
    assert np.all(true > 0.02) and np.all(np.abs(np.asarray(found) - true) < 0.5 * true + 0.01), (found, true)


def test_a_value_of_the_wrong_kind_and_a_bug_are_one_sentence(tmp_path, capsys, monkeypatch):
    """Issue 38: write_capture caught only its own errors; a word where a number goes ended in a TypeError
    traceback. The kind is named before rendering; anything else is one sentence, its traceback with --debug."""
    with pytest.raises(SystemExit) as e:
        main([str(tmp_path / "a"), *SMALL, "pattern.spacing_px=abc"])
    assert e.value.code == 2 and "pattern.spacing_px=abc: a number (its default: 4.0)" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()

    def broken(*args, **kwargs):
        return {}["missing"]

    monkeypatch.setattr("nerif.write_capture.write_capture", broken)
    with pytest.raises(SystemExit) as e:
        main([str(tmp_path / "b"), *SMALL])
    said = capsys.readouterr().err
    assert e.value.code == 2 and "nerif stopped on KeyError: 'missing' (add --debug to see where it arose)" in said
    assert not (tmp_path / "b").exists()
    with pytest.raises(KeyError):
        main([str(tmp_path / "c"), *SMALL, "--debug"])
