"""Receding-horizon MPC in the env: re-plan the rest of the cycle from the measured state.

Every ``replan_every`` control steps the controller reads the tip pose,
velocity and fill from the observation, solves the trajectory optimisation
for the remaining time of the cycle (shrinking horizon: the same ``N``
intervals over less time; the end-out-of-the-pile constraint stays) with a
few solver iterations, warm started from the previous re-plan's last iterate (primal and dual; the first
re-plan of a cycle from the remaining part of the plan being executed): the real-time-iteration idea, where
the optimisation converges over successive control steps instead of within one. ``solver="sqp"`` (the
default) is the real-time iteration itself: one QP per re-plan (CasADi's ``sqpmethod``, one iteration, QP
solver ``daqp``), initialised by a converged IPOPT solve at the first re-plan of the cycle, with IPOPT as the
fallback whenever an SQP re-plan is not usable; ``solver="ipopt"`` runs up to ``max_iter`` (8) IPOPT
iterations per re-plan with IPOPT's warm-start settings. The new plan is tracked
with feed-forward velocity plus proportional feedback
(:class:`~wheelloader.envs.scripted.PathTracker`). The solver status is
checked every time: a converged solve, or an unconverged one whose last
iterate satisfies the constraints (primal infeasibility at most
``feasible_tolerance``), is used; a failed, infeasible or non-finite solve
keeps the last used plan; with none, a retreat (lift the bucket out of the
pile) is tracked.
Every solve is recorded in :attr:`MPCController.history`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, Loader, Pile, SoilParams, as_soil
from wheelloader.estimator.checks import check_choice, check_int, check_range
from wheelloader.estimator.errors import PlanningError

from .cycle import cycle_duration, default_start, optimizer_for
from .trajectory import Plan, PlannerOptions, StartState, TrajectoryOptimizer
from .verify import verify_plan

#: Statuses of IPOPT (and sqpmethod) the controller accepts as a usable plan.
ACCEPTED_STATUSES = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
#: The MPC's solver by default (``benchmarks/planner.py`` measures both side by side).
DEFAULT_MPC_SOLVER = "sqp"
#: Solver iterations per re-plan by solver: IPOPT a few, the SQP's real-time iteration one QP.
DEFAULT_MAX_ITER = {"ipopt": 8, "sqp": 1}


@dataclass
class SolveRecord:
    """One MPC solve: when, how long (wall and this process's CPU time [s]), what the solver said, what the
    controller did with it, which solver made the plan (``"sqp"``, ``"ipopt"`` or ``"ipopt (fallback)"``) and its
    primal infeasibility (IPOPT's, or the SQP's largest constraint violation)."""

    step: int
    remaining: float
    seconds: float
    status: str
    iterations: int
    accepted: bool
    action: str
    solver: str = "ipopt"
    cpu_seconds: float = math.nan
    infeasibility: float = math.nan


class MPCController:
    """Shrinking-horizon MPC for one digging cycle of ``BucketLoadingEnv``.

    Parameters
    ----------
    soil : SoilParams, preset name or dict
        Parameters the controller plans with (calibrated, nominal or true).
    pile : Pile
        Surface at the start of the cycle.
    duration : float
        Cycle duration the controller aims for [s].
    bucket, loader : optional
        Must match the env's.
    control_rate : float
        Env control rate [Hz].
    replan_every : int
        Control steps between re-plans (default 6: 10 Hz at 60 Hz).
    intervals : int
        Intervals of the MPC's optimisation (default 12).
    min_remaining : float
        Below this remaining time [s] the controller stops re-planning and tracks the last plan.
    initial_plan : Plan, optional
        A full-cycle plan to start from (warm start of the first solve; tracked if that solve fails).
    options : PlannerOptions, optional
        Weights and margins (``intervals`` is overridden).
    reference_weight : float
        Weight [1/m^2] of staying near the plan being executed (keeps successive
        re-plans from jumping between local optima).
    solver : {"sqp", "ipopt"}
        The re-plans' solver (default :data:`DEFAULT_MPC_SOLVER`, ``"sqp"``: the real-time iteration, one QP
        per re-plan, with IPOPT at the first re-plan of a cycle and as the fallback of an SQP re-plan that
        is not usable; ``"ipopt"``: IPOPT alone). Sets the ``solver`` of the optimizer's
        :class:`PlannerOptions` (its ``qp_solver`` is the QP solver).
    max_iter : int, optional
        Iteration limit per re-plan (default :data:`DEFAULT_MAX_ITER`: 8 IPOPT iterations, or 1 SQP
        iteration; at most ``options.max_iter``): a few Newton steps per control step, each re-plan
        continuing from the previous one's last iterate. A re-plan that stops
        at the limit is used when its last iterate satisfies the constraints
        (primal infeasibility at most ``feasible_tolerance``): feasible,
        not yet proven optimal; otherwise the last accepted plan goes on. IPOPT's fallback and first
        solves run up to 8 iterations (at most ``options.max_iter``).
    feasible_tolerance : float
        Largest primal infeasibility of an unconverged iterate that is still
        used (default 1e-4: 0.1 mm on positions, 1e-4 of the force limits).
        An unconverged warm re-plan above it is still used when it passes the NumPy
        check (:func:`~wheelloader.planner.verify_plan`, a millisecond or two on
        the remaining cycle): feasible for the model the env simulates.
    exit_min_fill : float
        The env's end-of-cycle rule (``BucketLoadingEnv``'s option), for the
        re-plans and their check (default 0).
    """

    def __init__(self, soil: SoilParams | str | dict, pile: Pile, duration: float, *, bucket: Bucket | None = None,
                 loader: Loader | None = None, control_rate: float = 60.0, replan_every: int = 6,
                 intervals: int = 12, min_remaining: float = 0.4, initial_plan: Plan | None = None,
                 options: PlannerOptions | None = None, reference_weight: float = 20.0, max_iter: int | None = None,
                 feasible_tolerance: float = 1e-4, exit_min_fill: float = 0.0,
                 solver: str = DEFAULT_MPC_SOLVER) -> None:
        check_int("replan_every", replan_every, error=PlanningError)
        check_range("duration", duration, 0.0, None, low_open=True, error=PlanningError)
        check_range("control_rate", control_rate, 0.0, None, low_open=True, error=PlanningError)
        from dataclasses import replace

        self.soil = as_soil(soil)
        self.pile = pile
        self.duration = float(duration)
        self.bucket = bucket or Bucket()
        self.loader = loader or Loader()
        self.rate = float(control_rate)
        self.replan_every = replan_every
        self.min_remaining = float(min_remaining)
        check_choice("solver", solver, tuple(DEFAULT_MAX_ITER), error=PlanningError)
        if max_iter is None:
            max_iter = DEFAULT_MAX_ITER[solver]
        check_int("max_iter", max_iter, minimum=1, error=PlanningError)
        base = options or PlannerOptions()
        mpc_options = replace(base, intervals=intervals, ipopt_warm_start=True, solver=solver,
                              max_iter=min(base.max_iter, max_iter),
                              # the same share of the horizon curls out
                              curl_out_intervals=min(round(base.curl_out_intervals * intervals / base.intervals),
                                                     max(intervals // 2 - 1, 0)))
        self.optimizer = TrajectoryOptimizer(self.bucket, self.loader, mpc_options)
        # the SQP's first solve of a cycle and its fallback: IPOPT on the same NLP
        self.fallback = None if solver == "ipopt" else TrajectoryOptimizer(
            self.bucket, self.loader, replace(mpc_options, solver="ipopt", compiled=False,
                                              max_iter=min(base.max_iter, DEFAULT_MAX_ITER["ipopt"])))
        self.initial_plan = initial_plan
        self.reference_weight = float(reference_weight)
        self.feasible_tolerance = float(feasible_tolerance)
        self.exit_min_fill = float(exit_min_fill)
        self.history: list[SolveRecord] = []
        self.reset()

    def reset(self) -> None:
        """Start a new cycle (clears the plan, the tracker and the history)."""
        from wheelloader.envs.scripted import PathTracker

        self.step_index = 0
        self.history = []
        self.plan: Plan | None = self.initial_plan
        self._plan_start = 0.0
        self._tracker = (PathTracker(self.initial_plan.path(self.rate), self.loader, self.rate)
                         if self.initial_plan is not None else None)
        self.optimizer.reset_warm_start()
        if self.fallback is not None:
            self.fallback.reset_warm_start()

    @property
    def failures(self) -> int:
        """Solves that were not accepted."""
        return sum(not r.accepted for r in self.history)

    def solve_times(self, cpu: bool = False) -> np.ndarray:
        """Wall time (``cpu``: this process's CPU time) of every solve so far [s]."""
        return np.array([r.cpu_seconds if cpu else r.seconds for r in self.history])

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Action for ``obs``; re-plans every ``replan_every`` steps."""
        k = self.step_index
        now = k / self.rate
        remaining = self.duration - now
        if k % self.replan_every == 0 and remaining >= self.min_remaining:
            self._replan(obs, k, remaining)
        if self._tracker is None:
            self._tracker = self._retreat(obs)
        self.step_index += 1
        return self._tracker(obs)

    # ------------------------------------------------------------------ internals
    def _replan(self, obs: np.ndarray, k: int, remaining: float) -> None:
        from wheelloader.envs.scripted import PathTracker

        start = StartState.from_observation(obs, self.bucket.capacity, self.optimizer.options.force_payload)
        guess = self._remaining_guess(k / self.rate)
        tic, cpu = time.perf_counter(), time.process_time()
        # after a solve in this cycle, the solver continues from its last iterate (primal and dual);
        # at the first one (or after an error) from the remaining part of the plan being executed
        warm = bool(self.history) and not self.history[-1].status.startswith("error")
        try:
            if self.fallback is None:
                plan, usable, solver = *self._solve(self.optimizer, start, remaining, guess, warm), "ipopt"
            else:
                plan, usable, solver = None, False, "ipopt"
                if warm:  # the real-time iteration: one SQP step from the plan being executed, shifted to now
                    try:
                        plan, usable = self._solve(self.optimizer, start, remaining, guess, True, shift=True)
                    except PlanningError:  # IPOPT's turn (its error, if any, is the one recorded)
                        usable = False
                    solver = "sqp" if usable else "ipopt (fallback)"
                if not usable:  # IPOPT from the remaining plan; the SQP continues from its solution
                    plan, usable = self._solve(self.fallback, start, remaining, guess, False, check=warm)
                    self.optimizer.warm_start_from(self.fallback)
        except PlanningError as exc:
            self.history.append(SolveRecord(k, remaining, time.perf_counter() - tic, f"error: {exc}", 0, False,
                                            self._fallback_name(), "", time.process_time() - cpu))
            return
        seconds = time.perf_counter() - tic
        if usable:
            self.plan = plan
            self._plan_start = k / self.rate
            self._tracker = PathTracker(plan.path(self.rate), self.loader, self.rate)
            action = "new plan"
        else:
            action = self._fallback_name()
        self.history.append(SolveRecord(k, remaining, seconds, plan.status, plan.iterations, usable, action,
                                        solver, time.process_time() - cpu,
                                        float(plan.raw.get("primal_infeasibility", math.nan))))

    def _solve(self, optimizer: TrajectoryOptimizer, start: StartState, remaining: float,
               guess: BucketPath | None, warm: bool, shift: bool = False, check: bool | None = None
               ) -> tuple[Plan, bool]:
        """One re-plan with ``optimizer`` and whether its plan is usable (``shift``: from ``guess`` with the
        last solve's multipliers, else from the last iterate when ``warm``; ``check``, default ``warm``: an
        unconverged, infeasible-looking plan is judged by the NumPy check)."""
        plan = optimizer.solve(self.soil, self.pile, start, remaining,
                               initial_guess=guess if shift or not warm else None,
                               warm=warm, reference=guess, reference_weight=self.reference_weight,
                               exit_min_fill=self.exit_min_fill)
        feasible = plan.raw.get("primal_infeasibility", math.inf) <= self.feasible_tolerance
        usable = (plan.status in ACCEPTED_STATUSES or feasible) and _finite(plan)
        if not usable and (warm if check is None else check) and _finite(plan):
            # a warm re-plan continues from the last iterate: where it has not converged yet, it is used when
            # the NumPy re-simulation of the rest of the cycle passes every check
            usable = verify_plan(plan, self.soil, self.pile, self.bucket, self.loader, optimizer.options,
                                 rate=self.rate, exit_min_fill=self.exit_min_fill).ok
        return plan, usable

    def _fallback_name(self) -> str:
        return "kept the last feasible plan" if self._tracker is not None else "retreat"

    def _remaining_guess(self, now: float) -> BucketPath | None:
        plan = self.plan
        if plan is None:
            return None
        t = plan.t - plan.t[0]
        elapsed = now - self._plan_start
        if elapsed <= 0.0:
            return plan.path(self.rate)
        if elapsed >= t[-1] - 1e-6:
            return None
        tt = np.concatenate([[elapsed], t[t > elapsed + 1e-9]])
        return BucketPath(tt - elapsed, np.interp(tt, t, plan.x), np.interp(tt, t, plan.z),
                          np.interp(tt, t, plan.blade_angle), "remaining plan")

    def _retreat(self, obs: np.ndarray):
        """Lift the bucket straight up 0.5 m over one second, blade curled (the safe fallback)."""
        from wheelloader.envs.scripted import PathTracker

        x, z, th = float(obs[0]), float(obs[1]), float(obs[2])
        t = np.linspace(0.0, 1.0, 61)
        path = BucketPath(t, np.full_like(t, x), z + 0.5 * t, th + (math.radians(40.0) - th) * t, "retreat")
        return PathTracker(path, self.loader, self.rate)


def _finite(plan: Plan) -> bool:
    arrays = (plan.x, plan.z, plan.blade_angle, plan.vx, plan.vz, plan.omega)
    return all(bool(np.all(np.isfinite(a))) for a in arrays) and math.isfinite(plan.energy)


def make_env_policy(env: Any, soil: SoilParams | str | dict | None = None, **kwargs: Any) -> MPCController:
    """An MPC controller for ``env`` (a ``BucketLoadingEnv`` or a wrapper of one).

    Plans with ``soil`` (default: the env's current simulator soil, i.e. an
    oracle on the plant or the calibrated soil on a twin) on the env's start
    pile, starting from a full-cycle plan that passes the NumPy check (tracked
    while re-plans fail); call it after ``env.reset()``. The controller re-plans from the
    env's current pile when :meth:`MPCController.reset` is called after a new
    ``env.reset()`` only if you build a new one: use one controller per cycle.
    """
    base = env.unwrapped
    cfg = base.cfg
    pile = base.start_pile
    params = base.soil if soil is None else as_soil(soil)
    start = default_start(pile, cfg)
    duration = cycle_duration(pile, start)
    if "initial_plan" not in kwargs:
        # a full-cycle plan to start from: the first re-plan is warm-started from it, and it is tracked
        # for as long as re-plans fail (only when the NumPy check accepts it)
        opt = optimizer_for(cfg.bucket, cfg.loader, kwargs.get("options"))
        plan = opt.solve(params, pile, start, duration, exit_min_fill=cfg.exit_min_fill)
        if verify_plan(plan, params, pile, cfg.bucket, cfg.loader, opt.options, rate=cfg.control_rate,
                       exit_clearance=cfg.exit_clearance, exit_min_fill=cfg.exit_min_fill).ok:
            kwargs["initial_plan"] = plan
    kwargs.setdefault("exit_min_fill", cfg.exit_min_fill)
    return MPCController(params, pile, duration, bucket=cfg.bucket, loader=cfg.loader,
                         control_rate=cfg.control_rate, **kwargs)
