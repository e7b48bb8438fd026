"""Planning between cycles: the next cycle's plan and the MPC that executes it.

:func:`plan_next_cycle` is what the cycle-to-cycle loop (``wheelloader.adaptation``) and
``wheelloader plan`` call: a full-cycle trajectory optimisation on the carved pile with the calibrated
parameters, checked against the NumPy model, re-planned with wider margins when the check fails, and
handed over with an :class:`~wheelloader.planner.mpc.MPCController` that re-plans during the cycle.

Budgets are IPOPT iteration counts, so the same inputs give the same plan on a quiet and on a busy
machine; a wall-time limit (``PlannerOptions.max_wall_time``) is an opt-in safety cap whose firing the
outcome reports.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, Loader, PayloadOptions, Pile, SoilParams, as_soil
from wheelloader.estimator.checks import check_int
from wheelloader.estimator.errors import PlanningError
from wheelloader.estimator.payload import exit_angle_profile
from wheelloader.estimator.quantise import better, quantise_pile, quantise_soil

from .cycle import cautious_options, cycle_duration, default_start, optimizer_for
from .kept import KEPT_OBJECTIVE_SCALE, KeptTerms, evaluate, fixed_kept_fill
from .mpc import ACCEPTED_STATUSES, MPCController
from .trajectory import Plan, PlannerOptions, StartState, TrajectoryOptimizer
from .verify import PlanCheck, verify_plan


@dataclass
class PlanOutcome:
    """What a planning step returned.

    Attributes
    ----------
    path : BucketPath or None
        The path to dig (None when planning failed and there is no fallback yet).
    success : bool
        Whether the planner itself succeeded.
    message : str
        Solver status or fallback note.
    seconds : float
        Wall time of the planning step [s] (measured, reported; nothing depends on it).
    controller : callable or None
        Optional closed-loop controller ``obs -> action`` (e.g. MPC); when None
        the path is tracked with :class:`~wheelloader.envs.scripted.PathTracker`.
    plan : Plan or None
        The optimiser's last plan (also when it failed the check).
    check : PlanCheck or None
        The NumPy re-simulation of that plan.
    first_failures : list of str
        Why the first plan failed the check, when it was re-planned with wider margins.
    """

    path: BucketPath | None
    success: bool
    message: str
    seconds: float
    controller: Callable[[np.ndarray], np.ndarray] | None = None
    plan: Plan | None = None
    check: PlanCheck | None = None
    first_failures: list[str] = field(default_factory=list)


#: IPOPT iterations between two NumPy checks of the iterate (each takes a few milliseconds).
CHECK_EVERY = 10
#: The solve stops once the best iterate that passes the check has improved the objective (in bucket fills)
#: by less than STALL_TOLERANCE over the last STALL_CHECKS checks. (2 saves ~10 iterations a plan but changed 2
#: of 10 plans of the learned MPM loop, gravel seed 0 cycle 5 to 59.4 from 44.2 kJ/m^3 kept:
#: docs/results/between_cycles.md.)
STALL_CHECKS = 3
STALL_TOLERANCE = 0.01
#: An iterate is kept only once it loads this fraction of the bucket (by the NumPy check).
ITERATE_MIN_FILL = 0.5
#: How far below its target (a fraction of the capacity) the kept fill of a plan may be under the kept objective.
KEPT_TOLERANCE = 0.01
#: Under the kept objective the NumPy check ends the cycle at a hop out of the soil once this share of the env's
#: ``exit_min_fill`` is loaded. Measured (benchmarks/kept_lookahead.py --quick, gravel seed 0, cycle 1): an
#: early iterate that hopped out at 3.5 % planned fill passed the check at 5 %, and the env, tracking it with
#: noise, ended the cycle there with 0.011 m^3 dug.
KEPT_EXIT_SHARE = 0.5
#: A plan that loads less than this fraction of the bucket (by the NumPy check) is not used: the tip may
#: stay out of the soil, and a loader too weak to dig would otherwise "plan" a cycle in the air.
MIN_FILL = 0.1


def _dug(check: PlanCheck) -> float:
    """What a checked plan loads into the bucket for :data:`MIN_FILL` and :data:`ITERATE_MIN_FILL` [m^3]: the
    carved volume (under the payload force models ``check.fill`` is the kept soil, at most the payload's heap,
    ~0.5 of the capacity with the default payload: no iterate reached ITERATE_MIN_FILL and every plan of the
    MPM loop's ours with ``"fee-payload"`` on the committed piles failed, 6 of 8)."""
    return check.carved if math.isfinite(check.carved) else check.fill


def _flag_note(flags: dict[str, int]) -> str:
    """The validity flags that fired (samples per flag), without "tip out of soil"."""
    fired = [f"{name}: {count}" for name, count in flags.items() if count and name != "tip out of soil"]
    return f" [{', '.join(fired)}]" if fired else ""


def plan_next_cycle(params: SoilParams | str | dict, pile: Pile, *, start: StartState | None = None,
                    bucket: Bucket | None = None, loader: Loader | None = None,
                    options: PlannerOptions | None = None, control_rate: float = 60.0, mpc: bool = True,
                    replan_every: int = 6, replan_within: float | None = None,
                    replan_within_iterations: int | None = None, energy_weight: float | None = None,
                    initial_guess: Any = None, exit_min_fill: float = 0.0, force_model: str | None = None,
                    payload: PayloadOptions | None = None, give_up_iterations: int | None = None) -> PlanOutcome:
    """Plan the next cycle on ``pile`` with ``params``; return a ``PlanOutcome`` for the adaptation loop.

    The plan is accepted only when the NumPy re-simulation
    (:func:`verify_plan`) passes every check (when IPOPT stopped without
    success, e.g. at its iteration limit, the message says the plan is feasible
    but not proven optimal); otherwise the outcome says why
    (``success=False``) and the loop falls back. With
    ``mpc`` the outcome carries an :class:`MPCController` (warm-started with
    the plan) that re-plans every ``replan_every`` steps during the cycle.
    Every :data:`CHECK_EVERY` IPOPT iterations the iterate is checked too; the
    best one that passes (by the NumPy model's fill against energy, loading at
    least :data:`ITERATE_MIN_FILL` of the bucket) is kept, and the solve stops
    once it has improved by less than :data:`STALL_TOLERANCE` over
    :data:`STALL_CHECKS` checks (a rule on the iterates, so as deterministic as
    the iteration limit). A plan loading less than :data:`MIN_FILL` is not used.
    When no iterate passes, the plan is re-planned (at most twice) with wider
    margins, unless ``replan_within_iterations`` is given and the IPOPT
    iterations spent so far exceed it (an iteration budget: with
    ``options.max_iter`` it bounds the planning work, the same on any
    machine), or the opt-in wall-time cap ``replan_within`` [s] has passed.
    ``give_up_iterations``: a re-plan (never the first solve) with no iterate passing the check after this many
    IPOPT iterations (counted at the checks) stops there, as at its limit: a plan that will fail ends sooner in
    the loop's fallback (an iteration count, the same on any machine); None: re-plans run to their limit.
    ``energy_weight`` overrides ``options.energy_weight`` (lambda per kJ).
    ``initial_guess`` (a ``BucketPath``, or a function of the pile returning
    one) is where IPOPT starts; default :func:`~wheelloader.planner.guess.surface_dig`
    (over the air to where the slope lets the tip dig, then at a constant depth).
    ``exit_min_fill`` is the env's (passed to :func:`verify_plan` and the NLP:
    the tip may leave the soil while less is loaded). ``force_model`` and ``payload`` override the
    options' (:attr:`PlannerOptions.force_model`): the adaptation loop plans with the model it calibrated
    (:attr:`~wheelloader.estimator.Calibration.force_model`).

    The planner plans with ``params`` and ``pile`` rounded to fixed grids
    (:func:`~wheelloader.estimator.quantise.quantise_soil`, :func:`~wheelloader.estimator.quantise.quantise_pile`)
    and keeps an iterate only when it beats the kept one by more than
    :data:`~wheelloader.estimator.quantise.TIE_RELATIVE` (the earlier stays on a near-tie): last-bit
    differences of the calibration (another CPU's BLAS kernels) then give the same plan.
    """
    tic = time.perf_counter()
    if give_up_iterations is not None:
        give_up_iterations = check_int("give_up_iterations", give_up_iterations, error=PlanningError)
    if force_model is not None or payload is not None:
        base = options or PlannerOptions()
        options = replace(base, force_model=base.force_model if force_model is None else force_model,
                          payload=base.payload if payload is None else payload)
    params = quantise_soil(as_soil(params))
    pile = quantise_pile(pile)
    opt = optimizer_for(bucket, loader, options)
    start = start or default_start(pile)
    duration = cycle_duration(pile, start)
    def over_budget(spent: int) -> bool:
        return ((replan_within_iterations is not None and spent > replan_within_iterations)
                or (replan_within is not None and time.perf_counter() - tic > replan_within))

    kept_objective = opt.options.objective == "kept_per_energy"
    min_kept = _kept_target(pile, opt, control_rate, exit_min_fill) if kept_objective else 0.0
    try:
        found = _search(opt, options, params, pile, start, duration, energy_weight=energy_weight,
                        initial_guess=initial_guess, exit_min_fill=exit_min_fill, control_rate=control_rate,
                        kept_objective=kept_objective, min_kept=min_kept, over_budget=over_budget,
                        give_up_iterations=give_up_iterations)
    except PlanningError as exc:
        return PlanOutcome(None, False, f"planning failed: {exc}", time.perf_counter() - tic)
    opt, plan, check, best = found.opt, found.plan, found.check, found.best
    spent, retried, first_failures = found.spent, found.retried, found.first_failures
    if best:
        plan, check = best["plan"], best["check"]
    seconds = time.perf_counter() - tic
    if not check.ok:
        return PlanOutcome(None, False, f"IPOPT: {plan.status}; plan fails the NumPy check: "
                           + "; ".join(check.failures) + _flag_note(check.details["flags"]) + retried, seconds,
                           plan=plan, check=check, first_failures=first_failures)
    if not best:
        return PlanOutcome(None, False, f"IPOPT: {plan.status}; the plan loads only "
                           f"{_dug(check) / opt.bucket.capacity:.0%} of the bucket by the NumPy check{retried}",
                           seconds, plan=plan, check=check, first_failures=first_failures)
    # a plan that passes every check of the NumPy re-simulation is feasible even when IPOPT stopped at its
    # iteration limit (then it is not proven optimal): use it and say so
    note = "" if plan.status in ACCEPTED_STATUSES else " (not proven optimal; feasible by the NumPy check)"
    head = f"IPOPT {plan.status} in {plan.iterations} it."
    if plan.status.startswith("iterate"):
        head, note = f"IPOPT {plan.status} of {spent}", " (the best that passes the NumPy check)"
    controller = None
    if mpc:
        controller = MPCController(params, pile, duration, bucket=opt.bucket, loader=opt.loader,
                                   control_rate=control_rate, replan_every=replan_every, initial_plan=plan,
                                   options=opt.options, exit_min_fill=exit_min_fill)
    path = plan.path(control_rate, name="planned")
    kept = _kept_note(plan, check, params, pile, opt, min_kept) if kept_objective else ""
    return PlanOutcome(path, True, f"{head}{note}{retried}; predicted fill "
                       f"{check.fill / opt.bucket.capacity:.0%}, {check.energy / 1e3:.1f} kJ{kept}", seconds,
                       controller, plan=plan, check=check, first_failures=first_failures)


@dataclass
class _Search:
    """What :func:`_search` found: the last optimiser and plan, its check, the best passing plan, the work."""

    opt: TrajectoryOptimizer
    plan: Plan
    check: PlanCheck
    best: dict[str, Any]
    spent: int
    retried: str
    first_failures: list[str]


def _search(opt: TrajectoryOptimizer, options: PlannerOptions | None, params: SoilParams, pile: Pile,
            start: StartState, duration: float, *, energy_weight: float | None, initial_guess: Any,
            exit_min_fill: float, control_rate: float, kept_objective: bool, min_kept: float,
            over_budget: Callable[[int], bool], give_up_iterations: int | None = None) -> _Search:
    """Solve, keep the best iterate that passes the NumPy check, re-plan with wider margins when none does."""
    retried = ""
    first_failures: list[str] = []
    spent = 0

    def checked(plan, opt):
        # under the kept objective a hop out of the soil counts as the env's end of the cycle from
        # KEPT_EXIT_SHARE of exit_min_fill loaded (see KEPT_EXIT_SHARE)
        share = KEPT_EXIT_SHARE if opt.options.objective == "kept_per_energy" else 1.0
        return verify_plan(plan, params, pile, opt.bucket, opt.loader, opt.options, rate=control_rate,
                           exit_min_fill=share * exit_min_fill)

    lam = opt.options.energy_weight if energy_weight is None else energy_weight
    give_up: list[int | None] = [None]  # the first solve runs to its limit; the re-plans give up (see above)
    best: dict[str, Any] = {}
    scores: list[float] = []

    def consider(plan, check, iterate: bool = False) -> None:
        # the NumPy model's objective (fill against energy, as the NLP's) of a plan that passes the check; an
        # iterate on the way counts only once it loads ITERATE_MIN_FILL of the bucket (not the air it starts in)
        score = -check.fill / opt.bucket.capacity + lam * check.energy / 1000.0
        useful = _dug(check) >= (ITERATE_MIN_FILL if iterate else MIN_FILL) * opt.bucket.capacity
        if kept_objective:  # the kept objective (planner.kept) by the NumPy check, its kept fill on target
            terms = _kept_terms(plan, check, params, pile, opt)
            score = terms.per_kept * opt.bucket.capacity / KEPT_OBJECTIVE_SCALE
            useful = useful and terms.kept >= min_kept - KEPT_TOLERANCE * opt.bucket.capacity
        if check.ok and useful and ("score" not in best or better(score, best["score"])):
            best.update(score=score, plan=plan, check=check)

    def checkpoint(plan) -> bool:
        # every CHECK_EVERY iterations: keep the best iterate that passes the check; stop once it has gained
        # less than STALL_TOLERANCE over the last STALL_CHECKS checkpoints, or (a re-plan, give_up_iterations)
        # once this solve has run that many iterations without an iterate that passes
        consider(plan, checked(plan, opt), iterate=True)
        scores.append(best.get("score", math.inf))
        if not best and give_up[0] is not None and len(scores) * CHECK_EVERY >= give_up[0]:
            return True
        return len(scores) > STALL_CHECKS and scores[-1 - STALL_CHECKS] - scores[-1] < STALL_TOLERANCE

    guess = initial_guess(pile) if callable(initial_guess) else initial_guess
    plan = opt.solve(params, pile, start, duration, energy_weight=energy_weight, initial_guess=guess,
                     exit_min_fill=exit_min_fill, checkpoint=checkpoint, checkpoint_every=CHECK_EVERY,
                     min_kept=min_kept)
    spent += plan.iterations
    check = checked(plan, opt)
    consider(plan, check)
    for level in (1, 2):
        if best or over_budget(spent):
            break
        # no iterate passed the check (the smooth CasADi surface can differ from a carved pile near its
        # kinks, and the path between the plan's nodes can graze a crest): re-plan with wider margins,
        # from the plan that failed
        first_failures = first_failures or list(check.failures)
        opt = optimizer_for(opt.bucket, opt.loader, cautious_options(options or PlannerOptions(), level))
        scores.clear()
        give_up[0] = give_up_iterations
        plan = opt.solve(params, pile, start, duration, energy_weight=energy_weight, initial_guess=plan,
                         exit_min_fill=exit_min_fill, checkpoint=checkpoint, checkpoint_every=CHECK_EVERY,
                     min_kept=min_kept)
        spent += plan.iterations
        check = checked(plan, opt)
        consider(plan, check)
        retried = f" (re-planned {level}x with wider margins after: {'; '.join(first_failures)})"
    return _Search(opt, plan, check, best, spent, retried, first_failures)


def _kept_note(plan: Plan, check: PlanCheck, params: SoilParams, pile: Pile, opt: TrajectoryOptimizer,
               min_kept: float) -> str:
    """The kept objective's part of the outcome's message: kept fill against its target, energy per m^3 kept."""
    terms = _kept_terms(plan, check, params, pile, opt)
    return (f"; kept {terms.kept / opt.bucket.capacity:.0%} (target {min_kept / opt.bucket.capacity:.0%}), "
            f"{terms.per_kept / 1e3:.1f} kJ/m^3 kept with the lift to {opt.options.kept_dump_height:.2f} m")


def _kept_target(pile: Pile, opt, rate: float, exit_min_fill: float) -> float:
    """The kept objective's least kept fill [m^3]: the options' ``kept_target`` or the fixed Bezier path's kept
    fill on ``pile`` (:func:`~wheelloader.planner.kept.fixed_kept_fill`), times ``kept_target_scale``."""
    options = opt.options
    if options.kept_target is not None:
        return options.kept_target_scale * options.kept_target * opt.bucket.capacity
    return options.kept_target_scale * fixed_kept_fill(pile, opt.bucket, options.kept_payload, rate, exit_min_fill)


def _kept_terms(plan: Plan, check: PlanCheck, params: SoilParams, pile: Pile, opt) -> KeptTerms:
    """The kept objective's terms of ``plan`` by the NumPy check (its carved fill and energy, exact lift); the
    payload's heap sees the blade angle as the tip leaves ``pile`` (``exit_angle_profile``, as
    :func:`~wheelloader.planner.kept.fixed_kept_fill` for the target), where its ``curl_gain`` is not 0."""
    options = opt.options
    exit_angle = float(plan.blade_angle[-1])
    if options.kept_payload.curl_gain != 0.0:
        exit_angle = float(exit_angle_profile(plan.blade_angle, pile.surface_height(plan.x) - plan.z)[-1])
    return evaluate(check.carved, check.energy, float(plan.z[-1]), params.gamma, opt.bucket.capacity,
                    options.kept_payload, options.kept_dump_height, exit_angle)
