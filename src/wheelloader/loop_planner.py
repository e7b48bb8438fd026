"""The planner the adaptation loop uses between cycles (:func:`default_planner`) and its budgets."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import replace

from wheelloader.estimator import PayloadOptions, Pile, SoilParams, WheelloaderError
from wheelloader.planner import LOOP_EXIT_MIN_FILL, PlannerOptions, PlanOutcome, optimizer_for, plan_next_cycle

#: Work budget of the plan between cycles: IPOPT iterations per solve. A plan stopped at this limit is used
#: only when it passes the NumPy check (feasible, not proven optimal); otherwise it is re-planned with wider
#: margins while at most the budget is spent, and then the loop falls back to
#: :func:`~wheelloader.planner.model_bezier_on_face`. An iteration count, not a wall time, so that the same
#: seed gives the same cycles on a quiet and on a busy machine.
BETWEEN_CYCLES_MAX_ITER = 130
#: Work budget of the plan and its re-plans with wider margins together [IPOPT iterations]: a re-plan starts
#: only while fewer have been spent. Twice :data:`BETWEEN_CYCLES_MAX_ITER`, so that a plan the NLP finds
#: infeasible on a carved pile can be re-planned twice (measured on the 3 plans of ours that failed in
#: ``benchmarks/adaptation.py``, cycles 4-5: with 130 each was re-planned once and none passed; with 260 one
#: passed, with 400 no more). Plans that pass at once spend no more.
BETWEEN_CYCLES_REPLAN_ITER = 2 * BETWEEN_CYCLES_MAX_ITER
#: A re-plan with wider margins in which no iterate has passed the NumPy check after this many IPOPT iterations
#: stops there (``plan_next_cycle(give_up_iterations=...)``): the plan ends in the Bezier fallback sooner. In the
#: committed loop runs a re-plan that rescued a plan had an iterate passing by iteration 50 of the re-plan (or
#: ended itself by 61); on the 20 replayed situations of docs/results/between_cycles.md no re-plan rescued one,
#: so every plan stays the same and a failing plan spends at most 130 + 2 x 70 iterations instead of 390.
BETWEEN_CYCLES_GIVE_UP_ITER = 70
#: The loop's planner constrains forces and the validity domain at every interval's midpoint too
#: (``PlannerOptions.midpoints``). On the piles the loop carves, plans that the NLP solved at its nodes failed
#: the NumPy check at 1-5 samples between them (blade too flat to a carved step, slope clamped). Measured on
#: the loops of ``benchmarks/adaptation.py`` (18 x 5 cycles; load about 4): plans passing the check ours 81 ->
#: 87 of 90, the oracle 80 -> 90; energy per m^3 ours / oracle 1.08 -> 1.04; median time between cycles
#: 0.41 -> 0.66 s. (With a wider rho margin as well, 8 or 10 deg, fewer passed.)
LOOP_PLANNER_MIDPOINTS = True


def default_planner(mpc: bool = False, failure_angle: str = "min_n_gamma", cut_angle: float | None = None,
                    fill_limit: float | None = None, heel_clearance: float | None = None,
                    end_blade_angle: float | None = None, curl_out_intervals: int = 0,
                    midpoints: bool | None = None, objective: str = "fill_energy",
                    lookahead: bool | str = False, descend_clearance: float | None = None,
                    payload: PayloadOptions | None = None,
                    compiled: bool = False) -> Callable[[SoilParams, Pile], PlanOutcome]:
    """The planner used between cycles.

    A full-cycle CasADi plan within :data:`BETWEEN_CYCLES_MAX_ITER` IPOPT
    iterations (with its re-plans at wider margins, :data:`BETWEEN_CYCLES_REPLAN_ITER` in all),
    checked with the NumPy model, tracked in the env; with
    ``mpc`` an MPC controller re-plans the rest of the cycle every 0.1 s
    (slower, see the planner benchmark). ``failure_angle``: the planner's
    force-model rule for beta*; ``cut_angle``: its opt-in cutting cone [rad]; ``fill_limit``: the largest
    planned fill as a share of the bucket's nominal capacity (None: the planner's default);
    ``heel_clearance``: the opt-in height of the bucket's heel above the surface [m];
    ``end_blade_angle``: the opt-in smallest blade angle at the end [rad], ``curl_out_intervals`` the last
    intervals in which the bucket then curls out of the pile; ``midpoints``: forces and validity also at the
    intervals' midpoints (default :data:`LOOP_PLANNER_MIDPOINTS` for the plan, off with ``mpc``, whose re-plans
    have a 20 ms budget) (:class:`~wheelloader.planner.PlannerOptions`); ``objective``: the planner's objective
    (``"kept_per_energy"``: the opt-in energy per m^3 of kept soil, :mod:`wheelloader.planner.kept`);
    ``lookahead``: choose each plan with the cycle after it in view
    (:func:`~wheelloader.planner.lookahead.plan_with_lookahead`): ``True`` or ``"full"`` three candidates each
    followed by the greedy plan of the next cycle, each plan within the same budgets as greedy's; ``"fast"``
    :data:`~wheelloader.planner.lookahead.FAST` (greedy and one candidate warm-started from it within 20 IPOPT
    iterations, the next cycle scored with the geometric Bezier placement; cheaper, and worse than greedy in the
    FEE env, ``docs/results/lookahead.md``); ``"kept"`` the full setting with
    :data:`~wheelloader.planner.lookahead.KEPT_CANDIDATES` (for the kept objective: the greedy plan and its kept
    target 5 % lower and higher); ``descend_clearance``: the opt-in height above the surface above
    which the tip may not move down [m]; ``payload``: the payload state of the kept objective (and of the payload
    force models; None: the model's default) (:class:`~wheelloader.planner.PlannerOptions`); ``compiled``:
    IPOPT's derivatives as C compiled once per machine (``PlannerOptions.compiled``; the same plans, bit for bit).
    """
    if lookahead not in (False, True, "fast", "full", "kept"):
        raise WheelloaderError(f"lookahead must be False, True, 'fast', 'full' or 'kept', got {lookahead!r}")
    extra = {} if fill_limit is None else {"fill_limit": fill_limit}
    if midpoints is None:
        midpoints = LOOP_PLANNER_MIDPOINTS and not mpc
    options = PlannerOptions(max_iter=BETWEEN_CYCLES_MAX_ITER, failure_angle=failure_angle, cut_angle=cut_angle,
                             heel_clearance=heel_clearance, end_blade_angle=end_blade_angle,
                             curl_out_intervals=curl_out_intervals, midpoints=midpoints, objective=objective,
                             descend_clearance=descend_clearance, payload=payload, compiled=compiled, **extra)
    # build the plan's NLP before the loop's timings start; those of the two wider-margin re-plans are built
    # when a plan first fails its check (once per process: planner.optimizer_for). Compiled derivatives are
    # made at the first plan that needs them: a loop that plans with another force model (the calibration's)
    # does not compile this NLP for nothing
    optimizer_for(options=replace(options, compiled=False))
    if lookahead:
        from wheelloader.planner.lookahead import FAST, KEPT_CANDIDATES, plan_with_lookahead

        setting = {"fast": FAST, "kept": {"candidates": KEPT_CANDIDATES}}.get(lookahead, {})
        return functools.partial(plan_with_lookahead, mpc=mpc, options=options,
                                 replan_within_iterations=BETWEEN_CYCLES_REPLAN_ITER,
                                 give_up_iterations=BETWEEN_CYCLES_GIVE_UP_ITER,
                                 exit_min_fill=LOOP_EXIT_MIN_FILL, **setting)
    return functools.partial(plan_next_cycle, mpc=mpc, options=options,
                             replan_within_iterations=BETWEEN_CYCLES_REPLAN_ITER,
                             give_up_iterations=BETWEEN_CYCLES_GIVE_UP_ITER, exit_min_fill=LOOP_EXIT_MIN_FILL)
