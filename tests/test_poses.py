"""The views' poses: rotations, rays moved and turned back, offsets fitted to the data and recovered."""
import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from nerif.data.scene import Scene, views_of
from nerif.geometry import arc_rig, rays_in_box, rig_axis
from nerif.solvers.poses import POSES, RefinedPoses, rotation_matrices
from tests.helpers import AMBIENT, BOX, analytic


def turned(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])


def given_scene(turns_deg) -> Scene:
    """Eight cameras over 160 deg whose rig says they are where they are, each turned about y by ``turns_deg``
    from where they truly stand; each view's observation is what its true camera measured, read through the pose
    the rig gives it (turned with it)."""
    true = arc_rig(n_cameras=8, span_deg=160.0, binning=40)
    given = [replace(c, position=turned(a) @ c.position, rotation=turned(a) @ np.asarray(c.rotation))
             for c, a in zip(true, turns_deg)]
    origins, dirs, pixel, starts = rays_in_box(BOX, given)
    eps = []
    for v, a in enumerate(turns_deg):
        R = torch.tensor(turned(a))
        d_true = dirs[starts[v]:starts[v + 1]].double() @ R  # R^T d: the true camera's ray through that pixel
        o_true = torch.as_tensor(true[v].position, dtype=torch.float64).expand_as(d_true)
        eps.append(analytic(o_true, d_true) @ R.T)  # turned with the camera into the frame the rig gives it
    eps = torch.cat(eps) * AMBIENT.delta_thre
    return Scene(box=BOX, ambient=AMBIENT, views=views_of(given), origins=origins, dirs=dirs, eps=eps.float(),
                 pixel=pixel, view_start=starts, perpendicular_only=True)


def test_rotation_matrices_are_rodrigues_exact_at_zero_and_orthonormal():
    omega = torch.tensor([[0.0, 0.0, 0.0], [0.0, math.radians(30.0), 0.0], [0.3, -0.2, 0.5]], dtype=torch.float64)
    R = rotation_matrices(omega)
    torch.testing.assert_close(R[0], torch.eye(3, dtype=torch.float64), rtol=0, atol=0)
    torch.testing.assert_close(R[1], torch.tensor(turned(30.0)))
    torch.testing.assert_close(R @ R.transpose(1, 2), torch.eye(3, dtype=torch.float64).expand(3, 3, 3))
    torch.testing.assert_close(R[2] @ omega[2], omega[2])  # the axis stays


@pytest.mark.parametrize("turns", [[2.0, -3.0, 1.5, -1.0, 3.0, -2.5, 0.5, -0.5], [0.0] * 8])
def test_turns_put_in_are_recovered_against_the_true_field_and_a_true_rig_stays(turns):
    scene = given_scene(turns)
    poses = RefinedPoses(rays_per_view=256).setup(scene, 100)
    for _ in range(3):
        poses.fit(analytic)
    found = np.degrees(poses.omega[:, 1].numpy())
    np.testing.assert_allclose(found, -np.asarray(turns), atol=0.05)
    assert abs(poses.omega.mean(0)).max() < 1e-12 and abs(poses.t.mean(0)).max() < 1e-12  # the gauge
    assert poses.report()["pose_rotation_max_deg"] < 3.1 and "pose_warning" not in poses.report()


def test_the_tilts_are_left_as_given_unless_asked_and_found_when_asked():
    """A rig whose cameras are tilted (rotated about the horizontal axis across each one's line of sight, about the
    probe centre) by 1.5 degrees one way or the other, their turns right: by default (turn and shift) no rotation
    off the rig's axis is made; with ``components=[turn, tilt, shift]`` the tilts are found."""
    tilts = [1.5, -1.5, 1.5, -1.5, 1.5, -1.5, 1.5, -1.5]
    true = arc_rig(n_cameras=8, span_deg=160.0, binning=40)
    across = [np.asarray(c.rotation)[:, 0] for c in true]  # each camera's image right: a tilt's axis
    R = [torch.tensor(rotation_matrices(torch.tensor(np.radians(a) * ax)[None])[0].numpy()) for a, ax in zip(tilts, across)]
    given = [replace(c, position=(r.numpy() @ c.position), rotation=r.numpy() @ np.asarray(c.rotation))
             for c, r in zip(true, R)]
    origins, dirs, pixel, starts = rays_in_box(BOX, given)
    eps = torch.cat([analytic(torch.as_tensor(true[v].position, dtype=torch.float64).expand(int(starts[v + 1] - starts[v]), 3),
                              dirs[starts[v]:starts[v + 1]].double() @ R[v]) @ R[v].T for v in range(8)])
    scene = Scene(box=BOX, ambient=AMBIENT, views=views_of(given), origins=origins, dirs=dirs,
                  eps=(eps * AMBIENT.delta_thre).float(), pixel=pixel, view_start=starts, perpendicular_only=True)
    kept = RefinedPoses().setup(scene, 100)
    found = RefinedPoses(components=["turn", "tilt", "shift"]).setup(scene, 100)
    for _ in range(3):
        kept.fit(analytic)
        found.fit(analytic)
    axis = torch.as_tensor(rig_axis(given))  # the tilted axes leave it 0.002 deg off y
    off_axis = kept.omega - (kept.omega @ axis)[:, None] * axis
    assert off_axis.abs().max() < 1e-12
    expected = -np.radians(tilts)[:, None] * np.stack(across)
    expected -= expected.mean(0)  # the gauge: the rig's mean frame stays
    np.testing.assert_allclose(np.degrees(found.omega.numpy()), np.degrees(expected), atol=0.05)


def test_moved_rays_render_the_field_as_the_camera_measured_it_and_other_rays_as_given():
    turns = [2.0, -3.0, 1.5, -1.0, 3.0, -2.5, 0.5, -0.5]
    scene = given_scene(turns)
    poses = RefinedPoses().setup(scene, 100)
    omega = torch.zeros_like(poses.omega)
    omega[:, 1] = -torch.tensor(np.radians(turns))
    poses.load_state_dict({"omega": omega, "t": poses.t, "fits": 0})
    o, d, turn = poses.rays(scene.origins[scene.ray_views()], scene.dirs)
    eps = poses.back({"eps": analytic(o, d)}, turn)["eps"]
    scale = float(scene.observed.abs().max())  # float32 rays 800 mm out: agreement to 1e-3 of the largest
    torch.testing.assert_close(eps.float(), scene.observed, atol=1e-3 * scale, rtol=0)  # the true rays, turned back
    away = torch.tensor([[0.0, 0.0, 900.0]])
    o2, d2, _ = poses.rays(away, torch.tensor([[0.0, 0.0, -1.0]]))
    torch.testing.assert_close(o2, away)  # a ray of no training camera (a held-out view's) is as given


def test_the_poses_are_kept_in_a_checkpoint_and_given_poses_change_nothing():
    scene = given_scene([1.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    poses = RefinedPoses().setup(scene, 100)
    poses.fit(analytic)
    again = RefinedPoses().setup(scene, 100)
    again.load_state_dict(poses.state_dict())
    torch.testing.assert_close(again.omega, poses.omega)
    given = POSES.build({"name": "given"}).setup(scene, 100)
    o, d, turn = given.rays(scene.origins[:1], scene.dirs[:1])
    assert turn is None and o is not None and given.report() == {}
    assert all(poses.due(10 * k) for k in range(1, 9)) and not poses.due(25) and not poses.due(90)
    assert again.free.tolist() == poses.free.tolist() and poses.free[:2].all()  # the views found off stay free


@pytest.mark.parametrize("settings, message", [
    ({"at": [0.5, 1.0]}, r"poses.at=\[0.5, 1.0\]: shares of the run's iterations"),
    ({"bound_deg": -1.0}, r"poses.bound_deg=-1.0: a positive number"),
    ({"steps": 0}, r"poses.steps=0"),
    ({"components": ["turn", "spin"]}, r"poses.components=\['turn', 'spin'\]: a non-empty list of turn, tilt, shift"),
    ({"components": []}, r"poses.components=\[\]: a non-empty list"),
])
def test_impossible_settings_are_one_sentence(settings, message):
    with pytest.raises(ValueError, match=message):
        POSES.build({"name": "refined", **settings})


def test_too_few_views_to_pin_each_pose_are_refused():
    scene = given_scene([0.0] * 8).select_views([0, 1, 2])
    with pytest.raises(ValueError, match=r"poses=refined: 3 training view\(s\) cannot pin"):
        RefinedPoses().setup(scene, 100)


def test_the_voxel_solver_refuses_refined_poses_before_any_data():
    from nerif.configs import group
    from nerif.solvers import SOLVERS
    from tests.helpers import tiny_config

    with pytest.raises(ValueError, match="poses=refined: the voxel solver keeps the rig's poses as given"):
        SOLVERS.build(group(tiny_config("solver=cgls", "poses=refined"), "solver"))


def test_a_run_with_refined_poses_fits_them_during_training_and_reports_them_per_view():
    from nerif.configs import group
    from nerif.data import DATASETS
    from tests.helpers import solver, tiny_config

    cfg = tiny_config("poses=refined", "poses.rays_per_view=32")
    s = solver(cfg, DATASETS.build(group(cfg, "data")))
    s.fit(checkpoint_every=10**9, progress=False)
    assert s.poses.fits == 8  # after 2, 4, ..., 16 of the 20 iterations
    assert len(s.report["pose_angle_deg"]) == s.scene.n_views == 6
    assert len(s.report["pose_translation_mm"][0]) == 3 and s.report["poses"] == "refined"
