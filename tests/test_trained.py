"""The contract of a trained field and where a run can carry a calibrated uncertainty
(:mod:`nerif.solvers.trained`)."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import torch

from nerif.solvers.trained import TrainedField, why_not
from tests.helpers import tiny_config, trained_on_half_the_box


def test_the_neural_solver_keeps_the_contract_and_the_voxel_solver_has_no_trained_field():
    from nerif.data import DATASETS
    from nerif.configs import group
    from nerif.masks import Masks
    from nerif.solvers import SOLVERS

    s, scene = trained_on_half_the_box(4)
    assert isinstance(s, TrainedField)
    cfg = tiny_config("solver=cgls")
    cgls = SOLVERS.build(group(cfg, "solver")).setup(DATASETS.build(group(cfg, "data")), Masks())
    assert not isinstance(cgls, TrainedField)
    assert why_not(cgls, field=True) == "solver=cgls has no trained field"


def test_a_clone_never_trained_is_the_trained_field_and_its_parameters_are_the_fields_own():
    """``clone(views, seed)`` without iterations: the field as trained (the kept average), predicting what it
    predicts; its parameters are the tensors a step changes, and changing them leaves the trained one as it was."""
    s, scene = trained_on_half_the_box(20)
    c = s.clone(list(range(scene.n_views)), seed=7)
    np.testing.assert_allclose(c.reconstruction(), s.reconstruction(), rtol=0, atol=1e-7)
    o, d = scene.origins[scene.ray_views()[:50]], scene.dirs[:50]  # each ray from its camera
    torch.testing.assert_close(c.predict(o, d), s.predict(o, d), rtol=0, atol=1e-9)
    params = c.parameters()
    assert params and all(p.requires_grad for p in params)
    loss = c.batch_loss(update_occupancy=False)[0]["loss"]
    grads = torch.autograd.grad(loss, params, allow_unused=True)
    assert any(g is not None and float(g.abs().max()) > 0 for g in grads)  # the batch's loss reaches them
    before = s.reconstruction()
    with torch.no_grad():
        for p in params:
            p.add_(0.1)
    assert not np.allclose(c.reconstruction(), before) and np.array_equal(s.reconstruction(), before)


def test_what_a_run_lacks_for_a_calibrated_uncertainty_is_said_one_condition_at_a_time():
    s, scene = trained_on_half_the_box(4)  # 5 training views, view 5 held out
    assert why_not(s, field=True, heldout=True, leave_out=3) == ""
    assert why_not(s, leave_out=4) == "5 training views cannot spare 4 a member and keep 2"
    s.scene = replace(scene, heldout=None)
    assert why_not(s, field=True, heldout=True).startswith("the data hold no view out")
    assert why_not(s, field=True) == ""  # the condition not asked for is not checked
    nothing = SimpleNamespace(name="mystery", scene=scene)
    assert why_not(nothing, field=True, heldout=True) == "solver=mystery has no trained field"  # the first one
