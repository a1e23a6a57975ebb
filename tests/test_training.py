"""The neural solver's training state (:mod:`nerif.solvers.training`): its settings checked, when it has converged,
what its steps drew, the weights a checkpoint ended on."""
import pytest
import torch

from nerif.solvers.training import Optimisation, SampleCounts, Training

TRAIN = {"rays_per_batch": 256, "views_per_batch": "all", "outside_fraction": 0.05, "stop_when_converged": 0.02,
         "stop_patience": 3, "lr": 5e-3, "betas": [0.9, 0.99], "eps": 1e-8, "lr_min": 1e-6, "table_decay": 1.0,
         "ema_decay": 0.98, "init_volume": None, "init_iterations": 300}


def test_convergence_compares_the_best_of_the_last_evaluations_with_the_best_before_them():
    t = Training.read(TRAIN)
    assert t.converged([1.0, 0.5, 0.4]) is None  # no more evaluations than the patience: nothing to compare yet
    assert t.converged([1.0, 0.5, 0.495, 0.496, 0.497]) is True  # 1 % better than 0.5: below the 2 % asked
    assert t.converged([1.0, 0.5, 0.48, 0.496, 0.497]) is False  # 4 % better, once: one good evaluation is enough
    assert t.converged([1.0, 0.5, 0.7, 0.8, 0.6]) is True  # worse throughout
    assert Training.read({**TRAIN, "stop_when_converged": None}).converged([1.0] * 10) is None  # never stops


@pytest.mark.parametrize("key, value, words", [
    ("rays_per_batch", 0, "rays per batch must be at least 1"),
    ("views_per_batch", 0, "train.views_per_batch must be a number of views"),
    ("stop_when_converged", 1.5, "train.stop_when_converged=1.5"),
    ("stop_patience", 0, "train.stop_patience=0"),
    ("outside_fraction", 1.0, "outside_fraction must be within"),
    ("ema_decay", -0.1, "train.ema_decay=-0.1"),
])
def test_a_setting_that_cannot_be_used_is_one_sentence_naming_it(key, value, words):
    with pytest.raises(ValueError, match=words):
        Training.read({**TRAIN, key: value})


def test_the_counts_of_the_steps_add_up_and_survive_a_checkpoint():
    c = SampleCounts()
    c.add(samples=300, rays=10, most=40, skipped=1)
    c.add(samples=100, rays=10, most=25, skipped=3)
    f = c.figures(seconds=2.0)
    assert f == {"samples_per_second": 200.0, "samples_per_ray_mean": 20.0, "samples_per_ray_max": 40,
                 "rays_skipped_fraction": 0.2}
    back = SampleCounts()
    back.load_state_dict(c.state_dict())
    assert back.figures(2.0) == f


def test_a_checkpoints_result_is_its_average_once_a_step_updated_it_else_its_trained_weights():
    weights = {"module.layer.weight": torch.ones(2), "module.layer.bias": torch.zeros(1), "n_averaged": torch.tensor(5)}
    kept = Optimisation.averaged_weights({"average": weights})
    assert set(kept) == {"layer.weight", "layer.bias"} and torch.equal(kept["layer.weight"], torch.ones(2))
    assert Optimisation.averaged_weights({"average": {**weights, "n_averaged": torch.tensor(0)}}) is None
    assert Optimisation.averaged_weights({"average": None}) is None
