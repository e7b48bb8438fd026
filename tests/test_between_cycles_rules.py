"""The loop's rules for the work between cycles (#33): a failing re-plan gives up at its iteration count, the
loop's planner passes its counts, and the loop uses compiled derivatives where a compiled run left them."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import pytest

import wheelloader.planner.next_cycle as next_cycle
from wheelloader.estimator import Bucket, Loader, Pile, PlanningError
from wheelloader.loop_planner import BETWEEN_CYCLES_GIVE_UP_ITER, BETWEEN_CYCLES_MAX_ITER, BETWEEN_CYCLES_REPLAN_ITER
from wheelloader.planner import PlannerOptions, codegen, plan_next_cycle
from wheelloader.planner.nlp import RULES


class _Iterate(SimpleNamespace):
    def path(self, rate, name):  # noqa: ARG002 - the interface of Plan.path
        return None


def _fake_planner(monkeypatch, passing_from: dict[int, int]) -> list[int]:
    """Replace the optimiser and the NumPy check: solve ``k`` (0: the first, 1-2: the re-plans) runs
    ``max_iter`` iterations in steps of the check interval; its iterates pass the check from iteration
    ``passing_from[k]`` on (never when absent). Returns the iterations each solve ran."""
    solves: list[int] = []
    bucket = Bucket()

    class Optimizer:
        def __init__(self, options):
            self.options, self.bucket, self.loader = options, bucket, Loader()

        def solve(self, *args, checkpoint=None, checkpoint_every=10, **kwargs):
            k, it = len(solves), 0
            while it < self.options.max_iter:
                it += checkpoint_every
                if checkpoint(_Iterate(status=f"iterate {it}", iterations=it, solve=k)):
                    break
            solves.append(it)
            return _Iterate(status="Maximum_Iterations_Exceeded", iterations=it, solve=k)

    def verify(plan, *args, **kwargs):
        start = passing_from.get(plan.solve)
        ok = start is not None and plan.iterations >= start
        fill = 0.6 * bucket.capacity if ok else 0.05 * bucket.capacity
        return SimpleNamespace(ok=ok, carved=fill, fill=fill, energy=5000.0, failures=[] if ok else ["tip backwards"],
                               details={"flags": {}})

    monkeypatch.setattr(next_cycle, "optimizer_for", lambda bucket=None, loader=None, options=None:
                        Optimizer(options or PlannerOptions()))
    monkeypatch.setattr(next_cycle, "verify_plan", verify)
    return solves


def _plan(**kwargs):
    return plan_next_cycle("gravel", Pile.trapezoid(), mpc=False, options=PlannerOptions(max_iter=130),
                           replan_within_iterations=260, **kwargs)


def test_a_replan_without_a_passing_iterate_gives_up_at_its_count(monkeypatch):
    solves = _fake_planner(monkeypatch, {})
    outcome = _plan(give_up_iterations=30)
    assert not outcome.success and "re-planned 2x" in outcome.message
    assert solves == [130, 30, 30]  # the first solve runs to its limit, each re-plan stops at 30
    solves.clear()
    assert not _plan().success
    assert solves == [130, 130, 130]  # without the count: each solve to its limit
    with pytest.raises(PlanningError, match="give_up_iterations"):
        _plan(give_up_iterations=0)


def test_the_first_solve_and_a_replan_with_a_passing_iterate_are_not_cut(monkeypatch):
    # the first solve's iterates pass from iteration 50: it runs on to the stall rule (2 checks without gain)
    solves = _fake_planner(monkeypatch, {0: 50})
    outcome = _plan(give_up_iterations=30)
    assert outcome.success and solves == [50 + next_cycle.STALL_CHECKS * next_cycle.CHECK_EVERY]
    # a re-plan whose iterates pass from iteration 20 is not stopped at 30
    solves = _fake_planner(monkeypatch, {1: 20})
    outcome = _plan(give_up_iterations=30)
    assert outcome.success and "re-planned 1x" in outcome.message
    assert solves == [130, 20 + next_cycle.STALL_CHECKS * next_cycle.CHECK_EVERY]


def test_the_loop_planner_passes_its_iteration_counts(monkeypatch):
    import wheelloader.loop_planner as loop_planner

    monkeypatch.setattr(loop_planner, "optimizer_for", lambda options: None)
    plan = loop_planner.default_planner(objective="kept_per_energy")
    assert plan.keywords["give_up_iterations"] == BETWEEN_CYCLES_GIVE_UP_ITER < BETWEEN_CYCLES_MAX_ITER
    assert plan.keywords["replan_within_iterations"] == BETWEEN_CYCLES_REPLAN_ITER
    assert plan.keywords["options"].compiled is False
    assert loop_planner.default_planner(compiled=True).keywords["options"].compiled is True


def test_plant_loop_unit_plans_with_compiled_derivatives_where_present(tmp_path, monkeypatch):
    """The loop turns :func:`~wheelloader.planner.nlp.compiled_if_present` on while it runs (and back after), and
    ``compiled`` reaches the loop's planner (``plant_adaptation.py --compiled``)."""
    import wheelloader.adaptation as adaptation
    from wheelloader.loop import plant_loop_unit
    from wheelloader.planner import PlanOutcome
    from wheelloader.references.fee_env import FEEEnvPlant

    seen = []

    def stub_planner(params, pile, **model):
        seen.append(RULES["compiled_if_present"])
        return PlanOutcome(None, False, "stub: no plan", 0.0)

    made = []
    monkeypatch.setattr(adaptation, "default_planner", lambda **kwargs: made.append(kwargs) or stub_planner)
    before = RULES["compiled_if_present"]
    for compiled in (False, True):
        plant_loop_unit(FEEEnvPlant(sensor_noise=0.0), "ours", "gravel", cycles=1, seed=0,
                        cache=tmp_path / str(compiled), compiled=compiled)
        assert made[-1]["compiled"] is compiled
    assert seen == [True, True] and RULES["compiled_if_present"] is before


@pytest.mark.slow
@pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")
def test_the_loops_plan_with_compiled_derivatives_is_the_virtual_machines(tmp_path, monkeypatch):
    """The loop's plan (the kept objective, ``fee-learned``, its check, stall and give-up rules) on a 10-interval
    NLP: compiled once (minutes of CPU), then found by its key under the loop's rule: the same path, bit for
    bit, and the same message."""
    import numpy as np

    from wheelloader.estimator.learned import default_learned_model
    from wheelloader.planner import cycle, nlp

    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    payload = default_learned_model().payload
    options = PlannerOptions(intervals=10, max_iter=BETWEEN_CYCLES_MAX_ITER, objective="kept_per_energy",
                             failure_angle="min_weight_force", force_model="fee-learned", payload=payload)
    pile = Pile.trapezoid()

    def fresh():  # a new process's memory: no NLP and no optimiser held (planner.optimizer_for keeps them)
        monkeypatch.setattr(nlp, "_CACHE", {})
        monkeypatch.setattr(cycle, "_OPTIMIZERS", {})

    def plan(opts):
        out = plan_next_cycle("gravel", pile, mpc=False, options=opts, replan_within_iterations=0,
                              give_up_iterations=BETWEEN_CYCLES_GIVE_UP_ITER)
        return out, (None if out.path is None else np.column_stack([out.path.x, out.path.z, out.path.blade_angle]))

    fresh()
    virtual, vm_path = plan(options)
    fresh()
    compiled, c_path = plan(replace(options, compiled=True))
    assert codegen.LOG[-1]["status"] == "compiled"
    fresh()
    previous = nlp.compiled_if_present(True)
    try:
        found, f_path = plan(options)
    finally:
        nlp.compiled_if_present(previous)
    assert codegen.LOG[-1]["status"] == "loaded"
    for other, path in ((compiled, c_path), (found, f_path)):
        assert other.success == virtual.success and other.message == virtual.message
        assert (path is None) == (vm_path is None)
        if path is not None:
            assert path.tobytes() == vm_path.tobytes()
