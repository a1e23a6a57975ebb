"""CPU threads of a run: how many to start with, and a tuner that keeps the fastest count while the machine's load
changes.

With every core in torch's thread pool, one other busy process makes each parallel region wait for the thread
that shares a core with it: on 2 cores a training step went from 30 ms to 70-150 ms, where one thread took 44 ms.
Idle, one thread is 1.5x slower than two. No fixed count wins both (nor does OpenMP's passive wait policy: 36 %
slower idle), so ``threads=auto`` starts from the cores other processes leave free and then times the steps
themselves (:class:`ThreadTuner`; ``benchmarks/threads.py``).
"""
from __future__ import annotations

import logging
import os
import time
from collections import deque
from typing import Optional

import numpy as np

from nerif.units import declare

log = logging.getLogger(__name__)

declare(cpu_threads="threads", cpu_threads_chosen="[iteration, threads]")


def usable_cores() -> int:
    """The cores this process may run on (its affinity mask where the system has one)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def thread_budget() -> int:
    """The most CPU threads a run may use: the usable cores (:func:`usable_cores`), capped by ``OMP_NUM_THREADS``
    where it is set (a scheduler's or a shell's share of the machine)."""
    cores = usable_cores()
    cap = os.environ.get("OMP_NUM_THREADS", "")
    return max(1, min(cores, int(cap))) if cap.isdigit() else cores


def _cpu_times() -> Optional[dict[int, tuple[float, float]]]:
    """Per core of the machine, (busy, total) jiffies since boot, from ``/proc/stat``; None where there is none."""
    try:
        with open("/proc/stat") as f:
            lines = [ln.split() for ln in f if ln.startswith("cpu") and ln[3:4].isdigit()]
        out = {}
        for ln in lines:
            fields = [float(x) for x in ln[1:9]]
            idle = fields[3] + (fields[4] if len(fields) > 4 else 0.0)  # idle + iowait
            out[int(ln[0][3:])] = (sum(fields) - idle, sum(fields))
        return out
    except (OSError, ValueError, IndexError):
        return None


def busy_cores(interval_s: float = 0.2) -> float:
    """Cores this process may use (:func:`usable_cores`) that other processes keep busy, averaged over
    ``interval_s`` while this one waits (0 where the system does not say: not Linux)."""
    a = _cpu_times()
    time.sleep(interval_s)
    b = _cpu_times()
    if not a or not b:
        return 0.0
    mine = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set(a)
    busy = 0.0
    for k in mine & set(a) & set(b):
        total = b[k][1] - a[k][1]
        busy += (b[k][0] - a[k][0]) / total if total > 0 else 0.0
    return busy


def resolve_threads(setting, parallel_jobs: int = 1) -> int:
    """CPU threads a run starts with: ``auto`` = the usable cores less those other processes keep busy now, for a
    job alone; :func:`thread_budget` shared evenly by ``parallel_jobs`` jobs running at once (either at most
    ``OMP_NUM_THREADS``, where set); or a positive number (at most the usable cores). One sentence for anything
    else."""
    cores = usable_cores()
    if setting == "auto":
        budget = thread_budget()
        if parallel_jobs > 1:
            return max(1, budget // parallel_jobs)
        return max(1, min(budget, round(cores - busy_cores())))
    if isinstance(setting, bool) or not isinstance(setting, int) or setting < 1:
        raise ValueError(f"threads={setting}: auto or a number of CPU threads (at least 1)")
    if setting > cores:  # more threads than cores only wait on each other (38x slower with 1000 on 2 cores)
        log.warning("threads=%d: this process may use %d core(s); running with %d", setting, cores, cores)
        return cores
    return setting


class ThreadTuner:
    """Keeps a CPU run at the fastest of a few thread counts under the machine's current load, by timing its own
    training steps: after ``warmup`` steps it runs ``probe_steps`` steps at each candidate and keeps the count
    with the lowest median step time (the kept count stays unless another is ``margin`` times faster); it probes
    again after ``period`` steps (twice as long each time the same count wins again, up to 8x), and at once when
    the kept count's median step drifts by more than ``slack`` times from what it was when chosen (another process
    started or ended).

    Args:
        cores: the most threads to try (the usable cores); candidates are ``cores``, ``cores - 1`` and
            ``cores // 2`` (at least 1).
        set_threads: sets the count (``torch.set_num_threads``).
    """

    def __init__(self, cores: int, set_threads, warmup: int = 10, probe_steps: int = 5, period: int = 100,
                 slack: float = 1.3, margin: float = 1.1):
        self.candidates = sorted({max(1, c) for c in (cores, cores - 1, cores // 2)}, reverse=True)
        self.set_threads, self.warmup, self.probe_steps = set_threads, warmup, probe_steps
        self.base_period, self.period, self.slack, self.margin = period, period, slack, margin
        self.current = self.candidates[0]
        self.queue: list[int] = []  # candidates still to time in this probe
        self.times: dict[int, list[float]] = {}
        self.chosen_ms: Optional[float] = None  # median step of the kept count when it was chosen
        self.recent: deque[float] = deque(maxlen=16)
        self.steps = 0  # steps seen
        self.steady = 0  # steps at the kept count since the last probe
        self.switches: list[tuple[int, int]] = []  # (step, threads) each time the kept count changed

    @property
    def enabled(self) -> bool:
        return len(self.candidates) > 1

    def start(self, threads: int) -> None:
        """The count the run starts with (:func:`resolve_threads`); a candidate too (on a busy machine it can be
        fewer than any of the others)."""
        self.candidates = sorted(set(self.candidates) | {threads}, reverse=True)
        self.current = threads
        self.set_threads(threads)

    def _probe(self) -> None:
        self.queue, self.times = list(self.candidates), {}
        self._use(self.queue[0])

    def _use(self, n: int) -> None:
        if n != self.current:
            self.current = n
            self.set_threads(n)

    def after_step(self, seconds: float) -> None:
        """Account one training step of ``seconds`` run at the current count; may change the count."""
        if not self.enabled:
            return
        self.steps += 1
        if self.steps == self.warmup:
            self._probe()
            return
        if self.queue:  # probing
            t = self.times.setdefault(self.current, [])
            t.append(seconds)
            if len(t) < self.probe_steps:
                return
            self.queue.pop(0)
            if self.queue:
                self._use(self.queue[0])
                return
            medians = {n: float(np.median(v)) for n, v in self.times.items()}
            best = min(medians, key=medians.get)
            held = self.switches[-1][1] if self.switches else None
            if held in medians and medians[best] * self.margin > medians[held]:
                best = held  # a near tie: the step-to-step noise, not the load, decides it
            same = best == held
            self.period = min(8 * self.base_period, 2 * self.period) if same else self.base_period
            if not same:
                self.switches.append((self.steps, best))
                log.debug("threads=auto: %d thread(s) (median step %s)", best,
                          ", ".join(f"{n}: {1e3 * m:.1f} ms" for n, m in sorted(medians.items())))
            self._use(best)
            self.chosen_ms, self.steady = 1e3 * medians[best], 0
            self.recent.clear()
            return
        if self.steps < self.warmup:
            return
        self.steady += 1
        self.recent.append(seconds)
        drift = (1e3 * float(np.median(self.recent)) / self.chosen_ms if len(self.recent) == self.recent.maxlen
                 else 1.0)
        if self.steady >= self.period or not 1 / self.slack < drift < self.slack:
            self._probe()

    @property
    def kept(self) -> int:
        """The count the last probe chose (the start's before any)."""
        return self.switches[-1][1] if self.switches else self.current

    def report(self) -> dict:
        """For ``metrics.json``: the count kept at the end (``cpu_threads``) and every count kept in turn, with
        the step it began (``cpu_threads_chosen``)."""
        return {"cpu_threads": self.kept, "cpu_threads_chosen": [[s, n] for s, n in self.switches]}
