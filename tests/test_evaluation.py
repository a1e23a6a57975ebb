"""The scores a user without a truth reads: the views' misfits against what the flow's noise allows."""
import numpy as np
import torch

from nerif.data.scene import scene_from_displacements
from nerif.evaluation import Evaluation
from nerif.geometry import arc_rig, rays_in_box
from tests.helpers import AMBIENT, BOX, analytic

NOISE = 0.02  # of the largest displacement, per component


def measured(swap=None):
    """Eight views of the three blobs (closed-form deflections) measured as image displacements with Gaussian noise
    of known size (``swap``: two views whose images are listed in each other's place), view 7 held out; and the
    noise [px]."""
    cams = arc_rig(n_cameras=8, span_deg=160.0, binning=10)
    origins, dirs, pixel, starts = rays_in_box(BOX, cams)
    exact = scene_from_displacements(BOX, AMBIENT, cams, [np.zeros((c.height, c.width, 2)) for c in cams],
                                     [np.ones((c.height, c.width), bool) for c in cams])
    u = exact.to_displacement(analytic(exact.origins[exact.ray_views()], exact.dirs) * AMBIENT.delta_thre)
    sigma = NOISE * float(u.abs().max())
    rng = np.random.default_rng(0)
    images = []
    for v, c in enumerate(cams):
        img = np.zeros((c.height * c.width, 2))
        img[exact.pixel[exact.view_slice(v)].numpy()] = u[exact.view_slice(v)].numpy()
        images.append(img.reshape(c.height, c.width, 2) + rng.normal(0.0, sigma, (c.height, c.width, 2)))
    if swap is not None:
        a, b = swap
        images[a], images[b] = images[b], images[a]
    ok = [np.ones((c.height, c.width), bool) for c in cams]
    left_out = [np.zeros((c.height, c.width), np.uint8) for c in cams]
    scene = scene_from_displacements(BOX, AMBIENT, cams, images, ok, left_out=left_out)
    return scene.split_views([7]), sigma


def exact(o, d):
    return analytic(o, d).float()


def test_each_view_is_explained_to_its_noise_by_the_true_field_and_a_swapped_pair_is_named():
    scene, sigma = measured()
    ev = Evaluation(scene, 100.0, 4096, 0)
    np.testing.assert_allclose(ev.view_noise_px, np.sqrt(2) * sigma, rtol=0.25)  # the vectors' noise, read back
    m = ev.view_misfits(exact)
    assert all(0.6 < r < 1.2 for r in m["view_misfit_over_noise"]), m
    assert Evaluation.contradicted(m) == ""
    swapped, _ = measured(swap=(1, 5))
    ev = Evaluation(swapped, 100.0, 4096, 0)
    m = ev.view_misfits(exact)
    said = Evaluation.contradicted(m)
    assert "training view(s) [1, 5] are explained far worse than the others" in said, m
    ev.view_noise_px[3] = np.nan  # a view whose noise cannot be read is left unscored, the others still are
    m = ev.view_misfits(exact)
    assert m["view_misfit_over_noise"][3] is None
    assert "training view(s) [1, 5] are explained far worse" in Evaluation.contradicted(m)


def test_a_heldout_view_missed_far_beyond_its_noise_and_the_training_views_is_said_in_words():
    scene, sigma = measured()
    ev = Evaluation(scene, 100.0, 4096, 0)
    trained = ev.view_misfits(exact)
    good = {**ev.heldout_errors(exact, every=True, photometric=False), **trained}
    assert 0.6 < good["heldout_misfit_over_noise"] < 1.2 and Evaluation.unexplained(good) == ""
    unseen = {**ev.heldout_errors(lambda o, d: torch.zeros_like(d), every=True, photometric=False), **trained}
    assert unseen["heldout_misfit_over_noise"] > 5
    assert Evaluation.unexplained(unseen).startswith("the reconstruction does not explain a view it did not see")
    # a fit that explains none of its views (too short, too coarse) is not a view it did not see
    untrained = ev.view_misfits(lambda o, d: torch.zeros_like(d))
    assert Evaluation.unexplained({**unseen, **untrained}) == ""
