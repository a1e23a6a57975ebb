"""Training in stages: what a stretch of steps fits, for how long, from which learning rate, and whether the held-out
views choose between its field and the one the stage before it left.

A data term hands the neural solver its stages (``stages(iterations)`` of :mod:`nerif.solvers.data_terms`): the
flow's deflections for the whole run, or the flow's first and the images' after. :class:`StagePlan` says which
stage holds an iteration and plans the cosine learning-rate schedules they run on; the solver runs any list of them,
an ensemble's member (:meth:`nerif.solvers.neural.NeuralSolver.member`) its own.
"""
from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass
from typing import Callable, Optional, Sequence

import torch

from nerif.units import declare, stage_key

log = logging.getLogger(__name__)

declare(chosen_by="(what chose the field kept: held-out images or held-out displacements)",
        text=("data_term_kept",), **{stage_key("images", "from_iteration"): "iterations"},
        containers={stage_key("flow"): "(the flow's field, each unit by its name here)",
                    stage_key("images"): "(the images' field, each unit by its name here)"})


@dataclass(frozen=True)
class Stage:
    """One stretch of training.

    Attributes:
        name: what it fits, as the log and ``metrics.json`` name it (``flow``, ``images``: ``images_stage``...).
        term: what each of its steps draws and scores: ``draw(iteration) -> RayBatch`` and
            ``terms(eps, batch, iteration) -> dict`` (a data term).
        iterations: its steps.
        lr: the cosine learning-rate schedule starts again at this share of each optimiser group's peak rate where
            the stage begins; None: the schedule of the stage before runs on through it (one cosine over both; the
            first stage's then starts at the peak).
        choose: at the end of the run the held-out views keep the better of this stage's field and the field the
            stage before it left (the last stage only).
    """

    name: str
    term: object
    iterations: int
    lr: Optional[float] = 1.0
    choose: bool = False


class StagePlan:
    """The stages of a run in order, from iteration ``start`` (an ensemble's member goes on from the run's count).

    Args:
        stages: the stages; those of no iteration are left out, at least one must remain.
        start: the iteration the first stage begins at.
    """

    def __init__(self, stages: Sequence[Stage], start: int = 0):
        self.stages = [s for s in stages if s.iterations > 0]
        if not self.stages:
            raise ValueError("a run needs at least one stage of at least one iteration")
        if any(s.choose for s in self.stages[:-1]) or (self.stages[-1].choose and len(self.stages) < 2):
            raise ValueError("only the last stage of several chooses against the stage before it")
        self.start = int(start)
        self.ends = [self.start + e for e in itertools.accumulate(s.iterations for s in self.stages)]

    @property
    def iterations(self) -> int:
        """The iteration the last stage ends at."""
        return self.ends[-1]

    def index(self, iteration: int) -> int:
        """The index of the stage that holds ``iteration`` (the last one from its end on)."""
        return next((i for i, end in enumerate(self.ends) if iteration < end), len(self.stages) - 1)

    def at(self, iteration: int) -> Stage:
        """The stage that holds ``iteration``."""
        return self.stages[self.index(iteration)]

    def ending(self, iteration: int) -> Optional[Stage]:
        """The stage that ends at ``iteration`` where another follows it, else None."""
        return next((s for s, end in zip(self.stages, self.ends[:-1]) if end == iteration), None)

    @property
    def chooser(self) -> Optional[Stage]:
        """The last stage where it chooses against the one before it, else None."""
        return self.stages[-1] if self.stages[-1].choose else None

    @property
    def before_chooser(self) -> Optional[Stage]:
        """The stage whose field the choosing stage's competes with."""
        return self.stages[-2] if self.chooser is not None else None

    def schedule(self, iteration: int) -> tuple[float, int]:
        """(share of the peak rate it starts at, its length in iterations): the cosine schedule that holds
        ``iteration``, over the stage that starts it and those after it that run on through it (``lr`` None)."""
        i = self.index(iteration)
        first, last = i, i
        while first > 0 and self.stages[first].lr is None:
            first -= 1
        while last + 1 < len(self.stages) and self.stages[last + 1].lr is None:
            last += 1
        begin = self.ends[first - 1] if first else self.start
        factor = self.stages[first].lr
        return (1.0 if factor is None else float(factor)), self.ends[last] - begin

    def restarts(self, iteration: int) -> bool:
        """Whether a stage begins at ``iteration`` with a schedule of its own."""
        ending = self.ending(iteration)
        return ending is not None and self.stages[self.stages.index(ending) + 1].lr is not None

    def cosine(self, optimizer: torch.optim.Optimizer, iteration: int,
               lr_min: float) -> torch.optim.lr_scheduler.CosineAnnealingLR:
        """The cosine annealing of the schedule that holds ``iteration``, from its share of each group's peak rate
        (the group's ``lr`` when first seen, kept as ``peak_lr``) down to ``lr_min``."""
        factor, length = self.schedule(iteration)
        for g in optimizer.param_groups:
            g.setdefault("peak_lr", g["lr"])
            g["lr"] = g["initial_lr"] = g["peak_lr"] * factor
        return torch.optim.lr_scheduler.CosineAnnealingLR(optimizer, T_max=length, eta_min=lr_min)

    def replan(self, scheduler: torch.optim.lr_scheduler.CosineAnnealingLR, optimizer: torch.optim.Optimizer,
               iteration: int) -> None:
        """A schedule restored from a checkpoint of a run planned for another length (``train.iterations`` changed
        on resume): as if planned so from the start, its rate now where that schedule has it."""
        planned, length = scheduler.T_max, self.schedule(iteration)[1]
        if planned == length:
            return
        t = scheduler.last_epoch
        scheduler.T_max = length
        for g, base in zip(optimizer.param_groups, scheduler.base_lrs):
            c = math.cos(math.pi * min(t, length) / length)
            g["lr"] = scheduler.eta_min + (base - scheduler.eta_min) * (1 + c) / 2
        scheduler._last_lr = [g["lr"] for g in optimizer.param_groups]
        log.info("the cosine learning-rate schedule, planned for %d iterations, now runs to %d: at iteration %d its "
                 "rate is %.3g", planned, self.iterations, t, optimizer.param_groups[0]["lr"])


class HeldoutChoice:
    """The held-out views' choice between the field the stage before the chooser leaves and the one the chooser
    (:attr:`StagePlan.chooser`, the last stage) ends on.

    Args:
        plan: the stages. figures: what the held-out views say of the field as it stands now
            (:meth:`nerif.evaluation.Evaluation.stage_figures`); None where the scene holds no held-out view.
        physical: the held-out displacements are in px (else sigma).
    Attributes:
        previous: where the stage before the chooser has ended, its field's ``weights`` and ``figures``, else None
            (kept in checkpoints).
    """

    def __init__(self, plan: StagePlan, figures: Optional[Callable[[], dict]], physical: bool):
        self.plan, self.figures, self.physical = plan, figures, physical
        self.previous: Optional[dict] = None

    def after_step(self, iteration: int, estimate: Callable[[], torch.nn.Module]) -> None:
        """Where the stage before the chooser ends at ``iteration``: the field it leaves (``estimate()``, the one
        evaluations use; asked for only then, as it may wait for the device) and what the held-out views say of
        it."""
        if self.figures is not None and self.plan.ending(iteration) is self.plan.before_chooser is not None:
            weights = {k: v.detach().clone() for k, v in estimate().state_dict().items()}
            self.previous = {"weights": weights, "figures": self.figures()}

    def choose(self) -> tuple[Optional[str], dict]:
        """At the end of the run: the name of the stage whose field the held-out views keep (:func:`choose`) and what
        :attr:`nerif.solvers.base.IterativeSolver.report` records of it; (None, {}) where there is nothing to choose
        (no chooser, no held-out view)."""
        last, before = self.plan.chooser, self.plan.before_chooser
        if last is None:
            return None, {}
        if self.previous is None:
            log.info("data_term=images: no held-out view to choose between the %s and the %s fields by; the %s is "
                     "kept", whose(before.name), whose(last.name), whose(last.name))
            return None, {}
        return choose(before, last, self.previous["figures"], self.figures(), self.physical)

    def settle(self, report: dict, fields: tuple) -> Optional[str]:
        """At the end of the run: :meth:`choose`, its record added to ``report``; where the held-out views keep the
        stage before the chooser, its weights put back into each of ``fields`` (modules). The kept stage's name, or
        None where nothing was chosen."""
        kept, found = self.choose()
        report.update(found)
        if kept is not None and kept != self.plan.chooser.name:
            for field in fields:
                field.load_state_dict(self.previous["weights"])
        return kept


def choose(before: Stage, last: Stage, old: dict, new: dict, physical: bool) -> tuple[str, dict]:
    """The name of the stage whose field the held-out views keep, and what :attr:`report` records of the choice:
    ``last``'s field (figures ``new``, :meth:`nerif.evaluation.Evaluation.stage_figures`) where it explains the
    held-out views' images better than ``before``'s (``old``) did, as the image term compares them
    (``heldout_image_misfit``), or where they hold no images their displacements (``heldout_misfit``; px where
    ``physical``, else sigma); said in the log. The held-out displacements are the flow's, with the flow's bias: over
    26 runs of the 13 independent captures (two seeds) they chose the field the truth prefers in 22, the held-out
    images in 26 (the B-spline's runs) and 25 (the band-limited picture's; the one miss a tie, issue 56)."""
    key = "heldout_image_misfit" if "heldout_image_misfit" in new else "heldout_misfit"
    kept = last.name if new[key] < old[key] else before.name
    unit, what = ((" (of the full range)", "images") if key == "heldout_image_misfit" else
                  (" px" if physical else " (sigma)", "displacements"))
    mine, theirs = whose(last.name), whose(before.name)
    if kept == before.name:
        log.info("data_term=images: the %s field explains the held-out views worse than the %s (%.4g against "
                 "%.4g%s RMS of their %s): the %s field is kept (data_term.choose_by_heldout=false keeps the %s)",
                 mine, theirs, new[key], old[key], unit, what, theirs, mine)
    else:
        log.info("data_term=images: the %s field explains the held-out views better than the %s (%.4g against "
                 "%.4g%s RMS of their %s) and is kept", mine, theirs, new[key], old[key], unit, what)
    return kept, {"data_term_kept": kept, "chosen_by": f"held-out {what}", stage_key(before.name): old,
                  stage_key(last.name): new}


def whose(name: str) -> str:
    """``flow`` -> ``flow's``, ``images`` -> ``images'``."""
    return name + ("'" if name.endswith("s") else "'s")
