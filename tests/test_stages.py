"""Training stages (nerif.solvers.stages): which stage holds an iteration, the cosine schedules they run on, a
resumed schedule re-planned, and the plans a run cannot have."""
import math

import pytest
import torch

from nerif.solvers.stages import Stage, StagePlan


def optimizer(lr: float = 1e-2) -> torch.optim.Optimizer:
    return torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=lr)


def rates(plan: StagePlan, lr: float = 1e-2, lr_min: float = 0.0) -> list[float]:
    """The rate of every step of ``plan``, restarted where a stage starts a schedule of its own."""
    opt = optimizer(lr)
    sched = plan.cosine(opt, plan.start, lr_min)
    out = []
    for t in range(plan.start, plan.iterations):
        out.append(opt.param_groups[0]["lr"])
        opt.step()
        sched.step()
        if plan.restarts(t + 1):
            sched = plan.cosine(opt, t + 1, lr_min)
    return out


def test_a_stage_of_its_own_schedule_restarts_the_cosine_at_its_share_of_the_peak():
    plan = StagePlan([Stage("flow", None, 10), Stage("images", None, 5, lr=0.2, choose=True)])
    r = rates(plan)
    assert r[0] == pytest.approx(1e-2) and r[5] == pytest.approx(1e-2 * (1 + math.cos(math.pi * 5 / 10)) / 2)
    assert r[10] == pytest.approx(0.2e-2) and r[12] == pytest.approx(0.2e-2 * (1 + math.cos(math.pi * 2 / 5)) / 2)
    assert plan.at(9).name == "flow" and plan.at(10).name == "images" and plan.at(99).name == "images"
    assert plan.ending(10).name == "flow" and plan.ending(15) is None and plan.ending(5) is None
    assert plan.chooser.name == "images" and plan.before_chooser.name == "flow"


def test_a_stage_without_a_rate_runs_on_the_schedule_before_it():
    joined = rates(StagePlan([Stage("flow", None, 10), Stage("images", None, 5, lr=None)]))
    single = rates(StagePlan([Stage("flow", None, 15)]))
    assert joined == pytest.approx(single, rel=1e-12)


def test_a_members_plan_starts_at_the_runs_count_from_its_own_rate():
    plan = StagePlan([Stage("flow", None, 4, lr=0.3)], start=100)
    assert plan.iterations == 104 and plan.schedule(100) == (0.3, 4) and plan.at(103).name == "flow"
    assert rates(plan)[0] == pytest.approx(0.3e-2)


def test_stages_of_no_iteration_are_left_out_and_only_the_last_chooses():
    plan = StagePlan([Stage("flow", None, 0), Stage("images", None, 5)])
    assert [s.name for s in plan.stages] == ["images"] and plan.chooser is None
    with pytest.raises(ValueError, match="at least one stage"):
        StagePlan([Stage("flow", None, 0)])
    with pytest.raises(ValueError, match="only the last stage"):
        StagePlan([Stage("flow", None, 3, choose=True), Stage("images", None, 5)])


def test_a_resumed_schedule_planned_for_fewer_iterations_goes_on_as_if_planned_so():
    short, longer = StagePlan([Stage("flow", None, 10)]), StagePlan([Stage("flow", None, 20)])
    opt = optimizer()
    sched = short.cosine(opt, 0, 0.0)
    for _ in range(6):
        opt.step()
        sched.step()
    longer.replan(sched, opt, 6)
    assert sched.T_max == 20
    assert opt.param_groups[0]["lr"] == pytest.approx(rates(longer)[6], rel=1e-12)
