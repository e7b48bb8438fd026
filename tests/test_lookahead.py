"""Two-cycle look-ahead (planner.lookahead, #33 item 2) with stub planners: choice, ties, failures."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from wheelloader.estimator import Pile, WheelloaderError
from wheelloader.planner import PlannerOptions, bezier_on_face
from wheelloader.planner.kept import KeptTerms
from wheelloader.planner.lookahead import FAST, KEPT_CANDIDATES, plan_with_lookahead, two_cycle_cost
from wheelloader.planner.next_cycle import PlanOutcome

CANDS = (("greedy", {}), ("fill limit 0.80", {"fill_limit": 0.80}), ("energy weight 0.04/kJ", {"energy_weight": 0.04}))


def _stub(fail: set[float] = frozenset(), shift: dict[float, float] | None = None):
    """A planner that digs the fixed path on the pile (moved down by ``shift[fill_limit]``), or fails for the
    fill limits in ``fail``; it records the options of every call."""
    calls = []

    def planner(params, pile, *, options, **kwargs):
        calls.append(options)
        if options.fill_limit in fail:
            return PlanOutcome(None, False, "stub failed", 0.0)
        path = bezier_on_face(pile).shifted(dz=-(shift or {}).get(options.fill_limit, 0.0))
        return PlanOutcome(path, True, f"stub {options.fill_limit}", 0.0)

    planner.calls = calls
    return planner


def test_two_cycle_cost_known_answer():
    a = KeptTerms(kept=0.1, lift_energy=0.0, energy=4000.0, per_kept=40000.0)
    b = KeptTerms(kept=0.05, lift_energy=0.0, energy=3500.0, per_kept=70000.0)
    assert two_cycle_cost(a, b) == pytest.approx(7500.0 / 0.15)
    assert two_cycle_cost(a, None) == pytest.approx(40000.0)
    assert math.isinf(two_cycle_cost(None, b))


def test_identical_candidates_tie_to_greedy_and_the_next_cycle_is_greedy():
    stub = _stub()
    out = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=stub)
    choice = out.lookahead
    assert choice.chosen == 0 and out.message.startswith("look-ahead chose greedy")
    # all three cost the same: the same path on the same pile, then the same greedy next cycle
    assert choice.costs[0] == choice.costs[1] == choice.costs[2] and math.isfinite(choice.costs[0])
    # every candidate's next cycle is planned with the greedy settings, on the carved pile
    assert [c.fill_limit for c in stub.calls] == [0.95, 0.95, 0.80, 0.95, 0.95, 0.95]
    assert [c.energy_weight for c in stub.calls][4:] == [0.04, 0.02]
    first, second = choice.cycles[0]
    assert first.kept > 0.0 and second.kept > 0.0


def test_failed_candidates_are_not_chosen():
    out = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(fail={0.95}))
    # the greedy settings fail (first cycle, and every second cycle): only the 0.80 candidate has a first cycle
    assert out.lookahead.chosen == 1 and math.isinf(out.lookahead.costs[0]) and math.isinf(out.lookahead.costs[2])
    assert out.success


def test_deterministic():
    a = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}))
    b = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}))
    assert a.lookahead.costs == b.lookahead.costs and a.lookahead.chosen == b.lookahead.chosen
    assert a.lookahead.costs[1] != a.lookahead.costs[0]
    assert PlannerOptions().fill_limit == 0.95


def test_the_loop_selects_it():
    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, default_planner
    from wheelloader.planner.lookahead import plan_with_lookahead as lookahead

    planner = default_planner(lookahead=True)
    assert planner.func is lookahead and planner.keywords["options"].max_iter == BETWEEN_CYCLES_MAX_ITER
    assert default_planner(objective="kept_per_energy").keywords["options"].objective == "kept_per_energy"
    assert default_planner(lookahead="fast").keywords["second"] == "bezier"
    full = default_planner(lookahead="full")
    assert "second" not in full.keywords and "candidates" not in full.keywords
    assert "second" not in planner.keywords  # True: the full look-ahead (the fast one lost to greedy)
    kept = default_planner(lookahead="kept", objective="kept_per_energy")
    assert kept.keywords["candidates"] == KEPT_CANDIDATES and "second" not in kept.keywords
    assert [dict(c).get("kept_target_scale", 1.0) for _, c in KEPT_CANDIDATES] == [1.0, 0.95, 1.05]
    with pytest.raises(WheelloaderError, match="lookahead"):
        default_planner(lookahead="deep")


def _recording_stub():
    """A planner that digs the fixed path, records each call's options and keywords, and reports a plan of
    ``options.max_iter`` IPOPT iterations."""
    calls = []

    def planner(params, pile, *, options, **kwargs):
        calls.append((options, kwargs))
        plan = SimpleNamespace(iterations=options.max_iter, tag=f"plan {len(calls)}")
        return PlanOutcome(bezier_on_face(pile), True, "stub", 0.0, plan=plan)

    planner.calls = calls
    return planner


def test_fast_lookahead_warm_starts_the_candidates_and_scores_the_next_cycle_without_ipopt():
    stub = _recording_stub()
    out = plan_with_lookahead("gravel", Pile.trapezoid(), options=PlannerOptions(max_iter=130), planner=stub,
                              replan_within_iterations=260, **FAST)
    assert len(stub.calls) == len(FAST["candidates"]) == 2  # one plan per candidate, none for the next cycle
    (greedy, kw0), (variant, kw1) = stub.calls
    assert greedy.max_iter == 130 and "initial_guess" not in kw0 and kw0["replan_within_iterations"] == 260
    assert variant.max_iter == FAST["candidate_iterations"] and variant.fill_limit == 0.80
    assert kw1["initial_guess"].tag == "plan 1" and kw1["replan_within_iterations"] == 0
    assert out.lookahead.iterations == 130 + FAST["candidate_iterations"]
    # the same path on the same pile, the same geometric next cycle: a tie, which greedy wins
    assert out.lookahead.chosen == 0 and out.lookahead.costs[0] == out.lookahead.costs[1]
    second = out.lookahead.cycles[0][1]
    assert second is not None and second.kept > 0.0


def test_fast_lookahead_without_a_greedy_plan_starts_cold():
    calls = []

    def planner(params, pile, *, options, **kwargs):
        calls.append(kwargs)
        if options.fill_limit == 0.95:
            return PlanOutcome(None, False, "stub failed", 0.0)
        return PlanOutcome(bezier_on_face(pile), True, "stub", 0.0)

    out = plan_with_lookahead("gravel", Pile.trapezoid(), planner=planner, **FAST)
    assert "initial_guess" not in calls[1] and out.lookahead.chosen == 1


def test_lookahead_settings_are_checked():
    with pytest.raises(ValueError, match="second"):
        plan_with_lookahead("gravel", Pile.trapezoid(), planner=_stub(), second="tree")
    with pytest.raises(ValueError, match="candidate_iterations"):
        plan_with_lookahead("gravel", Pile.trapezoid(), planner=_stub(), candidate_iterations=0)


def test_a_margin_keeps_greedy_unless_a_candidate_is_clearly_cheaper():
    free = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}))
    costs = free.lookahead.costs
    assert free.lookahead.chosen == min(range(len(costs)), key=lambda k: (costs[k], k))
    strict = plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}),
                                 margin=0.99)
    assert strict.lookahead.chosen == 0 and strict.lookahead.costs == costs
    gain = 1.0 - min(costs) / costs[0]
    if gain > 0.0:  # a margin just below the predicted gain lets the cheaper candidate win, just above does not
        assert plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}),
                                   margin=0.9 * gain).lookahead.chosen == free.lookahead.chosen
        assert plan_with_lookahead("gravel", Pile.trapezoid(), candidates=CANDS, planner=_stub(shift={0.80: 0.03}),
                                   margin=1.1 * gain).lookahead.chosen == 0
    with pytest.raises(ValueError, match="margin"):
        plan_with_lookahead("gravel", Pile.trapezoid(), planner=_stub(), margin=1.0)
