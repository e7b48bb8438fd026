"""Planning between cycles: the next cycle's plan and the MPC that executes it.

:func:`plan_next_cycle` is what the cycle-to-cycle loop
(:mod:`wheelloader.adaptation`) calls after each calibration: a full-cycle
trajectory optimisation on the carved pile with the calibrated parameters,
checked against the NumPy model, handed over with an
:class:`~wheelloader.planner.mpc.MPCController` that re-plans during the cycle.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

from wheelloader.estimator import Bucket, Loader, Pile, SoilParams, as_soil
from wheelloader.estimator.errors import PlanningError

from .mpc import ACCEPTED_STATUSES, MPCController
from .trajectory import PlannerOptions, StartState, TrajectoryOptimizer, first_rise
from .verify import verify_plan

#: Duration of the digging motion once the tip is at the face [s] (the paper's 4.67 s cycle).
DIG_DURATION = 4.67
#: Speed assumed for the approach through the air to a carved face [m/s].
APPROACH_SPEED = 0.6

_OPTIMIZERS: dict[tuple, TrajectoryOptimizer] = {}


def optimizer_for(bucket: Bucket | None = None, loader: Loader | None = None,
                  options: PlannerOptions | None = None) -> TrajectoryOptimizer:
    """A cached :class:`TrajectoryOptimizer` (the NLP is built once per settings)."""
    key = (bucket or Bucket(), loader or Loader(), options or PlannerOptions())
    if key not in _OPTIMIZERS:
        _OPTIMIZERS[key] = TrajectoryOptimizer(*key)
    return _OPTIMIZERS[key]


def _flag_note(flags: dict[str, int]) -> str:
    """The validity flags that fired (samples per flag), without "tip out of soil"."""
    fired = [f"{name}: {count}" for name, count in flags.items() if count and name != "tip out of soil"]
    return f" [{', '.join(fired)}]" if fired else ""


def cautious_options(options: PlannerOptions, level: int = 1) -> PlannerOptions:
    """Wider safety margins for a re-plan: per ``level``, angle margin x(1 + 0.6 level), fill limit and
    force margin x0.9^level."""
    return replace(options, rho_margin=(1.0 + 0.6 * level) * options.rho_margin,
                   fill_limit=0.9**level * options.fill_limit, force_margin=0.9**level * options.force_margin)


def default_start(pile: Pile, cfg: Any = None) -> StartState:
    """The env's nominal start pose: 0.10 m before the toe, 0.03 m above the ground, blade at -5 deg.

    With an env config ``cfg`` its ``start_pose`` is used instead.
    """
    if cfg is not None:
        x, z, th = cfg.start_pose
        return StartState(x, z, th)
    from wheelloader.envs.config import pile_toe

    return StartState(pile_toe(pile) - 0.10, float(pile.heights.min()) + 0.03, math.radians(-5.0))


def cycle_duration(pile: Pile, start: StartState) -> float:
    """:data:`DIG_DURATION` plus the time to cross the air between ``start`` and the (carved) face [s]."""
    x_face = first_rise(pile, start, 0.05, step=0.01)
    gap = 0.0 if x_face is None else x_face - start.x
    return DIG_DURATION + max(0.0, gap - 0.3) / APPROACH_SPEED


def plan_next_cycle(params: SoilParams | str | dict, pile: Pile, *, start: StartState | None = None,
                    bucket: Bucket | None = None, loader: Loader | None = None,
                    options: PlannerOptions | None = None, control_rate: float = 60.0, mpc: bool = True,
                    replan_every: int = 6, replan_within: float | None = None,
                    initial_guess: Any = None, exit_min_fill: float = 0.0) -> Any:
    """Plan the next cycle on ``pile`` with ``params``; return a ``PlanOutcome`` for the adaptation loop.

    The plan is accepted only when the NumPy re-simulation
    (:func:`verify_plan`) passes every check (when IPOPT stopped without
    success, e.g. at its iteration limit, the message says the plan is feasible
    but not proven optimal); otherwise the outcome says why
    (``success=False``) and the loop falls back. With
    ``mpc`` the outcome carries an :class:`MPCController` (warm-started with
    the plan) that re-plans every ``replan_every`` steps during the cycle.
    A plan that fails the check is re-planned (at most twice) with wider
    margins, unless ``replan_within`` [s] is given and has already passed
    (a time budget: with ``options.max_wall_time`` it bounds the planning time).
    ``initial_guess`` (a ``BucketPath``, or a function of the pile returning
    one) is where IPOPT starts; default a straight dig along the surface.
    ``exit_min_fill`` is the env's (passed to :func:`verify_plan`).
    """
    from wheelloader.adaptation import PlanOutcome

    tic = time.perf_counter()
    params = as_soil(params)
    opt = optimizer_for(bucket, loader, options)
    start = start or default_start(pile)
    duration = cycle_duration(pile, start)
    retried = ""
    first_failure = ""

    def checked(plan, opt):
        return verify_plan(plan, params, pile, opt.bucket, opt.loader, opt.options, rate=control_rate,
                           exit_min_fill=exit_min_fill)

    try:
        guess = initial_guess(pile) if callable(initial_guess) else initial_guess
        plan = opt.solve(params, pile, start, duration, initial_guess=guess)
        check = checked(plan, opt)
        for level in (1, 2):
            if check.ok or (replan_within is not None and time.perf_counter() - tic > replan_within):
                break
            # the smooth CasADi surface can differ from a (carved) pile near its kinks, and the path between
            # the plan's nodes can graze a crest: re-plan with wider margins, from the plan that failed
            first_failure = first_failure or "; ".join(check.failures)
            opt = optimizer_for(opt.bucket, opt.loader, cautious_options(options or PlannerOptions(), level))
            plan = opt.solve(params, pile, start, duration, initial_guess=plan)
            check = checked(plan, opt)
            retried = f" (re-planned {level}x with wider margins after: {first_failure})"
    except PlanningError as exc:
        return PlanOutcome(None, False, f"planning failed: {exc}", time.perf_counter() - tic)
    seconds = time.perf_counter() - tic
    if not check.ok:
        return PlanOutcome(None, False, f"IPOPT: {plan.status}; plan fails the NumPy check: "
                           + "; ".join(check.failures) + _flag_note(check.details["flags"]) + retried, seconds)
    # a plan that passes every check of the NumPy re-simulation is feasible even when IPOPT stopped at its
    # iteration limit (then it is not proven optimal): use it and say so
    note = "" if plan.status in ACCEPTED_STATUSES else " (not proven optimal; feasible by the NumPy check)"
    controller = None
    if mpc:
        controller = MPCController(params, pile, duration, bucket=opt.bucket, loader=opt.loader,
                                   control_rate=control_rate, replan_every=replan_every, initial_plan=plan,
                                   options=opt.options)
    path = plan.path(control_rate, name="planned")
    return PlanOutcome(path, True, f"IPOPT {plan.status} in {plan.iterations} it.{note}{retried}; predicted fill "
                       f"{check.fill / opt.bucket.capacity:.0%}, {check.energy / 1e3:.1f} kJ", seconds, controller)
