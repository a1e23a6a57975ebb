"""Scene families: the independent renderer against closed forms, and datasets written in the paper's format."""
from dataclasses import replace

import numpy as np
import pytest
import torch

from nerif.data.families import AMBIENT, FAMILIES, blob_deflection, blob_sum, render, write_dataset
from nerif.data.phantoms import gaussian_blob_deflection
from nerif.data.transforms import transforms
from nerif.geometry import ProbeBox


def _rays(n, seed=0, spread=20.0):
    """Horizontal-ish rays from 400 mm away, aimed at random points near the centre."""
    g = torch.Generator().manual_seed(seed)
    th = torch.rand(n, generator=g, dtype=torch.float64) * 2 * np.pi
    o = torch.stack([400 * torch.sin(th), 20 * torch.randn(n, generator=g, dtype=torch.float64),
                     400 * torch.cos(th)], -1)
    target = (torch.rand(n, 3, generator=g, dtype=torch.float64) * 2 - 1) * spread
    d = target - o
    return o, d / d.norm(dim=-1, keepdim=True)


BLOBS = (np.array([[0.0, 0.0, 0.0], [8.0, -5.0, 3.0], [-6.0, 12.0, 14.0]]), np.array([5.0, 3.0, 2.0]),
         np.array([-0.6, -0.3, -0.4]))


def test_closed_form_matches_the_unbounded_blob():
    """Inside a box far larger than the blob, the chord's erf terms are 1: the classic closed form (a different
    derivation, in ``nerif.data.phantoms``) must agree, perpendicular to the ray, to round-off."""
    box = ProbeBox((200, 200, 200), 1.0)
    o, d = _rays(200)
    eps, _ = blob_deflection(BLOBS[0][:1], BLOBS[1][:1], BLOBS[2][:1], box, o, d)
    ref = gaussian_blob_deflection(o, d, BLOBS[0][0], 5.0, -0.6)
    assert float((eps - ref).norm() / ref.norm()) < 1e-9


def test_quadrature_matches_the_closed_form_on_a_cut_box():
    """Simpson quadrature of the autograd gradient (the renderer of the non-blob families) against the erf closed
    form, on a box whose +z face cuts a blob (the chord's ends matter, the part along the ray too)."""
    box = ProbeBox((40, 50, 30), 1.0)
    o, d = _rays(400)
    sigma = blob_sum(*BLOBS)
    eps_q, path_q = render(sigma, box, o, d, step_mm=0.25)
    eps_c, path_c = blob_deflection(*BLOBS, box, o, d)
    assert float((eps_q - eps_c).norm() / eps_c.norm()) < 1e-3
    assert float((path_q - path_c).norm() / path_c.norm()) < 1e-3
    along = (eps_c * d).sum(-1)
    assert float(along.abs().max()) > 0.05 * float(eps_c.norm(dim=-1).max())  # the cut is seen along the rays


@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_families_are_flames_seeded(family):
    a, b = FAMILIES[family](0), FAMILIES[family](1)
    Ta, Tb = a.truth_T(), b.truth_T()
    assert Ta.min() >= AMBIENT.T0 - 1e-6 and Ta.max() < AMBIENT.T_max  # representable: sigma in (-1, 0]
    assert Ta.max() > AMBIENT.T0 + 500  # a flame
    assert np.abs(Ta - Tb).max() > 50  # the seed changes it
    np.testing.assert_array_equal(FAMILIES[family](0).truth_T(), Ta)


def test_dataset_round_trip(tmp_path):
    """write_dataset -> data=transforms: the same rays and, within 16-bit quantisation, the same deflections
    (perpendicular to each ray, in radians once scaled by T_max), and the truth on the probe grid."""
    flame = FAMILIES["plumes"](0)
    overrides = write_dataset(tmp_path / "ds", flame, binning=16)
    assert "data=transforms" in overrides and f"data.truth={tmp_path / 'ds' / 'truth_T.npy'}" in overrides
    probe = {"shape": list(flame.box.shape), "voxel_mm": flame.box.voxel_mm}
    scene = transforms(str(tmp_path / "ds"), probe, AMBIENT.T0, AMBIENT.n0, sigma_prior=None, T_max=AMBIENT.T_max,
                       binning=1, pitch_um=320.0, truth=str(tmp_path / "ds" / "truth_T.npy"))
    assert scene.n_views == 9 and scene.heldout.n_views == 2
    np.testing.assert_allclose(scene.truth_T, flame.truth_T())
    o = scene.origins[scene.ray_views()].double()
    eps, _ = flame.render(o, scene.dirs.double())
    eps = eps - (eps * scene.dirs.double()).sum(-1, keepdim=True) * scene.dirs.double()
    quantum = float(eps.abs().max()) * 2 / 65535
    err = (scene.eps.double() / AMBIENT.delta_thre - eps).abs().max()
    assert float(err) < 2 * quantum + 1e-6 * float(eps.abs().max())
    assert float(eps.norm(dim=-1).max()) > 0.1  # not a trivially empty image
    # the cameras are the arc rig's: the first one 800 mm out on +z
    np.testing.assert_allclose(scene.cameras[0].position, [0.0, 0.0, 800.0], atol=1e-6)
    with pytest.raises(ValueError, match="data.T_max"):
        transforms(str(tmp_path / "ds"), probe, AMBIENT.T0, AMBIENT.n0, sigma_prior=None,
                   truth=str(tmp_path / "ds" / "truth_T.npy"))
    with pytest.raises(ValueError, match="probe grid"):
        transforms(str(tmp_path / "ds"), {"shape": [30, 50, 30], "voxel_mm": 2.0}, AMBIENT.T0, AMBIENT.n0,
                   sigma_prior=None, T_max=AMBIENT.T_max, truth=str(tmp_path / "ds" / "truth_T.npy"))


def test_the_data_picked_weight_ignores_the_truth(tmp_path):
    """CGLS-TV over two weights on a small rendered flame, scored against its truth and against an absurd one
    (every voxel 2000 K): the errors against the truth change, the weight chosen by held-out rays does not."""
    from nerif.app import run
    from nerif.configs import compose
    from nerif.metrics import select_by_heldout

    flame = replace(FAMILIES["plumes"](1), box=ProbeBox((30, 50, 30), 2.0))  # the same extent, coarser
    overrides = write_dataset(tmp_path / "ds", flame, binning=16)
    absurd = tmp_path / "absurd.npy"
    np.save(absurd, np.full(flame.box.shape, 2000.0))
    chosen, truth_errors = [], []
    for truth in (str(tmp_path / "ds" / "truth_T.npy"), str(absurd)):
        runs = {lam: run(compose(overrides + ["data.binning=1", "data.pitch_um=320", f"data.truth={truth}",
                                              "solver=cgls", "solver.regularizer=tv", f"solver.lam={lam}",
                                              "solver.iterations=20", "train.progress=false"]),
                         tmp_path / f"{lam}-{len(chosen)}")
                for lam in (1e-3, 10.0)}
        chosen.append(select_by_heldout(runs))
        truth_errors.append([m["temperature_rmse_K"] for m in runs.values()])
    assert chosen[0] == chosen[1]
    assert min(truth_errors[1]) > 5 * max(truth_errors[0])  # the absurd truth was used by the errors
    with pytest.raises(ValueError, match="held-out"):
        select_by_heldout({1: {"temperature_rmse_K": 1.0}})
