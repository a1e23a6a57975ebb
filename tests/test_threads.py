"""CPU threads of a run: the count it starts with under the machine's load, and the tuner that keeps the fastest."""
import subprocess
import sys
import time

import pytest

from nerif.threads import ThreadTuner, busy_cores, resolve_threads, thread_budget, usable_cores


class Machine:
    """Step times of a CPU run as a function of its thread count and of the other processes' load: ``times[load]``
    maps each count to its step [s]. The tuner sees only the times of the steps it runs."""

    def __init__(self, times: dict):
        self.times, self.load, self.threads, self.trace = times, "idle", None, []

    def set_threads(self, n: int) -> None:
        self.threads = n

    def run(self, tuner: ThreadTuner, steps: int) -> None:
        for _ in range(steps):
            tuner.after_step(self.times[self.load][self.threads])
            self.trace.append(self.threads)


# measured on 2 cores (benchmarks/threads.py): idle, two threads are faster; beside a busy process, one is
TWO_CORES = {"idle": {2: 0.030, 1: 0.046}, "busy": {2: 0.085, 1: 0.045}}


def test_the_tuner_keeps_the_fastest_count_and_follows_the_load():
    m = Machine(TWO_CORES)
    tuner = ThreadTuner(2, m.set_threads)
    tuner.start(2)
    m.run(tuner, 300)
    assert tuner.kept == 2 and m.trace[-50:] == [2] * 50
    m.load = "busy"  # another process starts: the kept count's steps are 2.8x slower, so it probes at once
    m.run(tuner, 60)
    assert tuner.kept == 1 and m.trace[-20:] == [1] * 20
    m.load = "idle"  # it ends: one thread's steps barely change (45 -> 46 ms), the next periodic probe finds 2 faster
    m.run(tuner, 500)
    assert tuner.kept == 2
    assert [n for _, n in tuner.switches] == [2, 1, 2]
    # probing costs little: idle, at most 8 % of the steps ran at the slower count
    idle_steps = m.trace[-400:]
    assert idle_steps.count(1) <= 0.08 * len(idle_steps)


def test_a_count_that_wins_again_is_probed_less_often():
    m = Machine(TWO_CORES)
    tuner = ThreadTuner(2, m.set_threads, period=100)
    tuner.start(2)
    m.run(tuner, 1000)
    assert tuner.period == 800  # 100, then doubled each time the same count won, up to 8x
    assert m.trace.count(1) <= 20  # 5 steps a probe, at steps 10, 120, 330 and 740


def test_candidates_and_a_single_core():
    assert ThreadTuner(8, print).candidates == [8, 7, 4]
    busy = ThreadTuner(8, lambda n: None)
    busy.start(2)  # 6 of 8 cores busy at the start: 2 threads are tried as well
    assert busy.candidates == [8, 7, 4, 2] and busy.current == 2
    one = ThreadTuner(1, lambda n: pytest.fail("a single core has nothing to tune"))
    assert not one.enabled
    for _ in range(100):
        one.after_step(0.01)


def test_more_threads_than_cores_are_capped(caplog):
    cores = usable_cores()
    assert resolve_threads(1000) == cores and "threads=1000" in caplog.text
    assert resolve_threads(1) == 1
    with pytest.raises(ValueError, match="threads=many: auto or a number of CPU threads"):
        resolve_threads("many")


def test_parallel_jobs_share_the_cores():
    assert resolve_threads("auto", parallel_jobs=2 * usable_cores()) == 1


@pytest.mark.skipif(not sys.platform.startswith("linux") or usable_cores() < 2, reason="needs /proc/stat and 2 cores")
def test_auto_leaves_a_core_that_another_process_keeps_busy(monkeypatch):
    """``auto`` counts the cores other processes keep busy. Where the machine was already busy before the child
    started (another job: issue 47), the child's core cannot show on top, and ``auto`` must leave a core anyway."""
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)  # the suite's share (tests/conftest.py) would decide alone
    idle = busy_cores(0.3)
    p = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.3)
        busy = busy_cores(0.5)
        start = resolve_threads("auto")
    finally:
        p.kill()
        p.wait()
    if idle < usable_cores() - 1.2:  # room for the child's core to show
        assert busy > idle + 0.6, (idle, busy)  # one core's worth, seen from another process
    assert start <= usable_cores() - 1, (idle, busy, start)


def test_a_near_tie_keeps_the_count_it_has():
    """Steps 5 % faster at another count are the machine's noise, not its load: the kept count stays."""
    m = Machine({"idle": {2: 0.030, 1: 0.0285}})
    tuner = ThreadTuner(2, m.set_threads)
    tuner.start(2)
    m.run(tuner, 15)  # the first probe: 1 thread is 5 % faster and is kept (nothing held yet)
    assert tuner.kept == 1
    m.times["idle"] = {2: 0.0275, 1: 0.0285}  # now 2 threads are 3.5 % faster: within the margin
    m.run(tuner, 400)
    assert tuner.kept == 1 and [n for _, n in tuner.switches] == [1]


def test_omp_num_threads_caps_auto_and_the_tuner(monkeypatch):
    """A scheduler's share (``OMP_NUM_THREADS``) bounds what ``auto`` starts with and what the tuner tries."""
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert thread_budget() == 1 and resolve_threads("auto") == 1 and resolve_threads("auto", parallel_jobs=4) == 1
    assert not ThreadTuner(thread_budget(), lambda n: pytest.fail("one thread has nothing to tune")).enabled
    monkeypatch.setenv("OMP_NUM_THREADS", "999")
    assert thread_budget() == usable_cores()
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert thread_budget() == usable_cores()
