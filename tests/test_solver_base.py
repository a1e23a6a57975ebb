"""The loop every solver shares: evaluation cadence, early stop, checkpoints, Ctrl-C, resume, fixed rays."""
import os
import signal
import time

import pytest
import torch

from nerif.data import DATASETS
from nerif.evaluation import fixed_rays
from nerif.solvers.base import SOLVERS, DivergenceError, Interrupted, IterativeSolver

METRICS = {"flame_threshold_K": 1.0, "eval_rays_per_view": 4}


class Halving(IterativeSolver):
    """A solver whose state halves every step: converged once below ``tol``; Ctrl-C at iteration ``interrupt_at``."""

    name = "halving"

    def __init__(self, iterations=10, eval_every=3, tol=0.0, interrupt_at=None, diverge_at=None, sleep_s=0.0):
        super().__init__(iterations=iterations, eval_every=eval_every, metrics=METRICS, seed=0, label="halving")
        self.x, self.tol, self.interrupt_at, self.diverge_at, self.sleep_s = 1.0, tol, interrupt_at, diverge_at, sleep_s
        self.saved_at = []

    def step(self):
        if self.iteration == self.interrupt_at:
            raise KeyboardInterrupt
        if self.iteration == self.diverge_at:
            raise DivergenceError(f"the loss became nan at iteration {self.iteration}")
        time.sleep(self.sleep_s)
        self.x /= 2
        self._timed(0.001)
        return {"loss": self.x, "converged": self.x < self.tol}

    def evaluate(self):
        self.history.append({"iteration": self.iteration, "x": self.x})
        return self.history[-1]

    def state_dict(self):
        return {**super().state_dict(), "x": self.x}

    def save(self, path):
        self.saved_at.append(self.iteration)
        super().save(path)

    def load_state_dict(self, st):
        super().load_state_dict(st)
        self.x = st["x"]


def test_evaluates_every_eval_every_and_at_the_end(tmp_path):
    s = Halving(iterations=10, eval_every=3)
    last = s.fit(checkpoint_every=4, checkpoint=tmp_path / "ck.pt", progress=False)
    assert [h["iteration"] for h in s.history] == [3, 6, 9, 10] and last["x"] == 2.0**-10
    assert torch.load(tmp_path / "ck.pt", weights_only=False)["iteration"] == 10  # the last one, at the end
    assert s.timing()["iterations"] == 10 and s.timing()["ms_per_iteration"] == pytest.approx(1.0)


def test_a_converged_solver_stops_early():
    s = Halving(iterations=100, eval_every=50, tol=1e-3)
    s.fit(checkpoint_every=50, progress=False)
    assert s.iteration == 10 and s.history[-1]["iteration"] == 10  # 2^-10 < 1e-3


def test_ctrl_c_saves_a_checkpoint_that_resumes_exactly(tmp_path):
    s = Halving(iterations=10, interrupt_at=5)
    with pytest.raises(KeyboardInterrupt):
        s.fit(checkpoint_every=100, checkpoint=tmp_path / "ck.pt", progress=False)
    resumed = Halving(iterations=10)
    resumed.load(tmp_path / "ck.pt")
    assert resumed.iteration == 5 and resumed.x == 2.0**-5
    resumed.fit(checkpoint_every=100, progress=False)
    assert resumed.x == 2.0**-10 and [h["iteration"] for h in resumed.history] == [3, 6, 9, 10]


class SignalsInAFinalizer(Halving):
    """A solver whose step at ``signal_at`` drops an object whose finalizer sends the process ``signum``: the
    signal lands inside ``__del__``, where a raised exception is ignored."""

    def __init__(self, signum, signal_at, **kw):
        super().__init__(**kw)
        self.signum, self.signal_at = signum, signal_at

    def step(self):
        if self.iteration == self.signal_at:
            signum = self.signum

            class Dropped:
                def __del__(self):
                    os.kill(os.getpid(), signum)
                    for _ in range(1000):  # the handler runs here, between these bytecodes
                        pass

            Dropped()
        return super().step()


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM, signal.SIGUSR2])
def test_a_signal_that_lands_in_a_finalizer_still_stops_the_run_after_its_step(tmp_path, signum):
    own = signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL
    before = signal.signal(signum, own)
    try:  # as in a terminal (a shell's background job ignores SIGINT, and so does the run)
        s = SignalsInAFinalizer(signum, 4, iterations=10)
        with pytest.raises(Interrupted) as e:
            s.fit(checkpoint_every=100, checkpoint=tmp_path / "ck.pt", progress=False)
        assert e.value.signal_name == signal.Signals(signum).name
        assert s.iteration == 5 and torch.load(tmp_path / "ck.pt", weights_only=False)["iteration"] == 5
        assert signal.getsignal(signum) is own  # the handler is given back
    finally:
        signal.signal(signum, before)


def test_a_signal_ignored_on_entry_stays_ignored():
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        s = SignalsInAFinalizer(signal.SIGINT, 4, iterations=10)
        s.fit(checkpoint_every=100, progress=False)
        assert s.iteration == 10 and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, before)


def test_checkpoints_come_at_most_the_time_interval_apart(tmp_path):
    s = Halving(iterations=6, sleep_s=0.04)
    s.fit(checkpoint_every=1000, checkpoint_every_s=0.07, checkpoint=tmp_path / "ck.pt", progress=False)
    assert s.saved_at == [2, 4, 6]  # 0.08 s of steps between saves; the iteration cadence alone: [6]


def test_a_diverged_run_says_which_checkpoint_is_kept(tmp_path):
    with pytest.raises(DivergenceError, match="no checkpoint had been saved yet"):
        Halving(diverge_at=2).fit(checkpoint_every=5, checkpoint=tmp_path / "ck.pt", progress=False)
    with pytest.raises(DivergenceError, match=r"at iteration 7; the checkpoint of iteration 5 is kept"):
        Halving(diverge_at=7).fit(checkpoint_every=5, checkpoint=tmp_path / "ck.pt", progress=False)


def test_a_missing_checkpoint_and_bad_settings_are_one_sentence(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        Halving().load(tmp_path / "nope.pt")
    with pytest.raises(ValueError, match="iterations must be at least 1"):
        Halving(iterations=0)
    with pytest.raises(ValueError, match="evaluations every 0 iterations"):
        Halving(eval_every=0)


def test_fixed_rays_are_per_view_and_seeded():
    scene = DATASETS.build({"name": "synthetic", "render_supersample": 1, "T_max": 2000.0,
                            "rig": {"name": "arc", "n_cameras": 3, "binning": 40},
                            "phantom": {"name": "gaussian_blob", "shape": [16, 16, 16], "voxel_mm": 2.0}})
    a, b, c = fixed_rays(scene, 5, 0), fixed_rays(scene, 5, 0), fixed_rays(scene, 5, 1)
    assert torch.equal(a, b) and not torch.equal(a, c) and len(a) == 15 and len(set(a.tolist())) == 15
    assert scene.ray_views()[a].tolist() == [0] * 5 + [1] * 5 + [2] * 5


def test_the_registry_holds_both_solvers():
    assert SOLVERS.names() == ["cgls", "nerif"]
