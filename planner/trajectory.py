"""Full-cycle trajectory optimisation of the bucket path (CasADi + IPOPT): :class:`TrajectoryOptimizer`.

The NLP (direct transcription, constraints, objective) is built in
:mod:`.nlp`; the settings and start state are in :mod:`.options`, the result
in :mod:`.plan` and the initial guess in :mod:`.guess`. Their names are
re-exported here for code that imports them from this module.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from wheelloader.estimator import (
    DEFAULT_SLOPE_WINDOW,
    Bucket,
    BucketPath,
    Loader,
    Pile,
    PlanningError,
    SoilParams,
    as_soil,
)
from wheelloader.estimator.checks import check_range

from . import lanes
from .casadi_model import soil_vector
from .guess import face_position, first_rise, straight_dig, surface_dig
from .interrupt import guarded
from .nlp import handle
from .options import PlannerOptions, StartState
from .plan import Plan

__all__ = ["Plan", "PlannerOptions", "StartState", "TrajectoryOptimizer", "face_position", "first_rise",
           "straight_dig"]


class TrajectoryOptimizer:
    """Builds the NLP once and solves it for any soil, pile, start and duration.

    Parameters
    ----------
    bucket : Bucket, optional
        Bucket (width, edge, floor length, capacity are solver constants).
    loader : Loader, optional
        Speed, acceleration and force limits.
    options : PlannerOptions, optional
        Transcription and weights.

    Examples
    --------
    >>> opt = TrajectoryOptimizer()                                   # doctest: +SKIP
    >>> plan = opt.solve("gravel", Pile.trapezoid(), StartState(-0.1, 0.03, -0.087), duration=4.67)  # doctest: +SKIP
    """

    def __init__(self, bucket: Bucket | None = None, loader: Loader | None = None,
                 options: PlannerOptions | None = None) -> None:
        self.bucket = bucket or Bucket()
        self.loader = loader or Loader()
        self.options = options or PlannerOptions()
        for name, value, cls in (("bucket", self.bucket, Bucket), ("loader", self.loader, Loader),
                                 ("options", self.options, PlannerOptions)):
            if not isinstance(value, cls):
                raise PlanningError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")
        # the NLP and its solver stay in planner.nlp's cache, not here: a wider-margin variant of the NLP may take
        # its place in memory (nlp.build), and the next solve then builds it again
        self._nlp = handle(self.bucket, self.loader, self.options)
        self._nlp()  # the NLP now, not at the first solve
        self._lasts: dict[int, dict[str, np.ndarray]] = {}  # the last solution by lane (planner.lanes)

    @property
    def _last(self) -> dict[str, np.ndarray] | None:
        """The last solution of this thread's lane (:mod:`.lanes`): its warm start."""
        return self._lasts.get(lanes.current())

    @_last.setter
    def _last(self, value: dict[str, np.ndarray] | None) -> None:
        if value is None:
            self._lasts.pop(lanes.current(), None)
        else:
            self._lasts[lanes.current()] = value

    def _solver_and_monitor(self) -> tuple[Any, Any]:
        """This lane's IPOPT solver and its iteration callback (:mod:`.lanes`)."""
        solver, functions, _ = self._nlp()
        return solver, functions["monitor"]

    @property
    def _solver(self) -> Any:
        return self._nlp()[0]

    @property
    def _functions(self) -> dict[str, Any]:
        return self._nlp()[1]

    @property
    def _layout(self) -> dict[str, Any]:
        return self._nlp()[2]

    # ------------------------------------------------------------------ API
    @property
    def intervals(self) -> int:
        """N."""
        return self.options.intervals

    def solve(self, soil: SoilParams | str | dict, pile: Pile, start: StartState, duration: float, *,
              energy_weight: float | None = None, min_fill: float = 0.0, initial_guess: Plan | BucketPath | None = None,
              warm: bool = False, reference: BucketPath | None = None, reference_weight: float = 0.0,
              exit_min_fill: float = 0.0, checkpoint: Callable[[Plan], bool] | None = None,
              checkpoint_every: int = 10, min_kept: float = 0.0) -> Plan:
        """Plan a path from ``start`` on ``pile`` lasting ``duration`` seconds.

        Parameters
        ----------
        soil : SoilParams, preset name or dict
            Soil to plan with (calibrated parameters).
        pile : Pile
            Surface at the start of the cycle (depth is measured to it).
        start : StartState
            Start pose, velocity and fill.
        duration : float
            Cycle duration [s].
        energy_weight : float, optional
            lambda per kJ (default: the options').
        min_fill : float
            Lower bound on the final fill [m^3] (default 0: no bound).
        initial_guess : Plan or BucketPath, optional
            Where IPOPT starts; default the previous solution when ``warm``,
            else :func:`~wheelloader.planner.guess.surface_dig` (whose entry into
            the soil is then the face past which the tip stays in the soil).
        warm : bool
            Start from the previous solution (and its multipliers) if there is one; with an
            ``initial_guess``, from the guess with the previous solution's multipliers (the shifted warm start
            of the MPC's real-time iteration).
        reference : BucketPath, optional
            A path to stay close to (MPC: the plan being executed), weighted by
            ``reference_weight`` [1/m^2] on the mean squared tip-position distance.
        exit_min_fill : float
            The env's end-of-cycle rule (``BucketLoadingEnv``'s option of the same name, a fraction of the
            capacity): while less than it is loaded the tip may leave the soil (e.g. to pass over a carved
            wall) without ending the cycle, so the plan may too (default 0: it stays in the soil once past
            the face).
        checkpoint : callable, optional
            Called with the iterate as a :class:`Plan` (status ``"iterate k"``) every ``checkpoint_every``
            IPOPT iterations; returning True stops the solve there (IPOPT's ``User_Requested_Stop``). The
            caller keeps what it wants of the iterates (e.g. the best one that passes the NumPy check):
            a stop depends on the iterates only, so the result is as deterministic as without it.
        min_kept : float
            With ``objective="kept_per_energy"``: lower bound on the payload model's kept fill [m^3]
            (default 0: none; :func:`~wheelloader.planner.plan_next_cycle` sets the options' ``kept_target``).

        Returns
        -------
        Plan
            Always returned; check ``plan.success`` (and :func:`~wheelloader.planner.verify_plan`).
        """
        soil, lam, cap = self._checked(soil, start, duration, energy_weight, min_fill)
        n = self.intervals
        h = float(duration) / n
        check_range("reference_weight", reference_weight, 0.0, None, error=PlanningError)
        ref, reference_weight = self._reference_track(reference, reference_weight, h)
        lbx, ubx = self._bounds(pile, start)
        check_range("min_kept", min_kept, 0.0, None, error=PlanningError)
        if min_kept > 0.0 and "kept_end" not in self._layout:
            raise PlanningError("min_kept needs PlannerOptions(objective='kept_per_energy')")
        lbg, ubg = self._constraint_bounds(soil, min_fill, min_kept)
        args: dict[str, Any] = {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        face = self._start_point(args, soil, pile, start, duration, h, warm, initial_guess)
        check_range("exit_min_fill", exit_min_fill, 0.0, 1.0, error=PlanningError)
        free = [1.0, exit_min_fill * cap] if exit_min_fill > 0.0 else [0.0, 0.0]
        tail = np.concatenate([ref.ravel(), [reference_weight], [face], free])
        tic = time.perf_counter()
        # each node sees the surface through a window placed around its start position; a node that moves
        # out of its window's range is re-solved once, from where IPOPT stopped, with re-centred windows
        # (not after the wall-time limit: the NumPy check judges that iterate on the real pile)
        iterations = 0
        solver, monitor = self._solver_and_monitor()  # held for the whole solve (planner.nlp.build may drop them)
        try:
            for attempt in range(2):
                windows = self._windows(pile, start, args["x0"])
                args["p"] = p = np.concatenate([self._parameters(soil, pile, start, h, lam, windows), tail])
                if checkpoint is not None:
                    monitor.watch = _Watch(self, checkpoint, checkpoint_every, p, h, start, face, iterations,
                                           tic)
                sol = guarded(solver, **args)  # Ctrl-C is re-raised, never kept as a plan
                stats = dict(solver.stats())
                if isinstance(monitor.watch, _Watch) and monitor.watch.error is not None:
                    raise monitor.watch.error
                iterations += int(stats.get("iter_count", 0))
                w = np.array(sol["x"]).ravel()
                self._last = last = {"x": w, "lam_x": np.array(sol["lam_x"]).ravel(),
                                     "lam_g": np.array(sol["lam_g"]).ravel()}
                stopped = stats.get("return_status") in ("Maximum_WallTime_Exceeded", "User_Requested_Stop")
                if attempt == 1 or stopped or not self._outside_windows(windows, w):
                    break
                args.update(x0=w, lam_x0=last["lam_x"], lam_g0=last["lam_g"])
        finally:
            monitor.watch = None
        elapsed = time.perf_counter() - tic
        stats["iter_count"] = iterations
        if not stats.get("iterations"):  # sqpmethod: no primal infeasibility of its own; the largest violation
            stats["primal_infeasibility"] = _violation(w, np.array(sol["g"]).ravel(), args)
        plan = self._plan_from(w, p, h, start, stats, elapsed, float(sol["f"]))
        plan.raw["face"] = face
        return plan

    def _checked(self, soil: SoilParams | str | dict, start: StartState, duration: float,
                 energy_weight: float | None, min_fill: float) -> tuple[SoilParams, float, float]:
        """Check :meth:`solve`'s arguments; the soil, the energy weight lambda [1/kJ] and the capacity [m^3]."""
        soil = as_soil(soil)
        if not isinstance(start, StartState):
            raise PlanningError(f"start must be a StartState, got {type(start).__name__}")
        check_range("duration", duration, 0.2, 60.0, error=PlanningError)
        lam = self.options.energy_weight if energy_weight is None else energy_weight
        check_range("energy_weight", lam, 0.0, None, error=PlanningError)
        cap = self.bucket.capacity
        check_range("min_fill", min_fill, 0.0, cap, error=PlanningError)  # at most the bucket's capacity
        if start.fill > cap * (1 + 1e-9):
            raise PlanningError(f"start fill {start.fill} m^3 exceeds the bucket capacity {cap} m^3")
        return soil, lam, cap

    def _reference_track(self, reference: BucketPath | None, reference_weight: float,
                         h: float) -> tuple[np.ndarray, float]:
        """The reference path's tip positions at the n + 1 nodes and its weight (zeros and 0 without one)."""
        n = self.intervals
        ref = np.zeros((n + 1, 2))
        if reference is not None and reference_weight > 0.0:
            ts = np.arange(n + 1) * h
            rt = reference.t - reference.t[0]
            ref = np.column_stack([np.interp(ts, rt, reference.x), np.interp(ts, rt, reference.z)])
        else:
            reference_weight = 0.0
        return ref, reference_weight

    def _start_point(self, args: dict[str, Any], soil: SoilParams, pile: Pile, start: StartState, duration: float,
                     h: float, warm: bool, initial_guess: Plan | BucketPath | None) -> float:
        """Put IPOPT's start point (and warm multipliers) into ``args``; return the face past which the tip digs."""
        lbx, ubx = args["lbx"], args["ubx"]
        face = face_position(pile, start)
        if warm and self._last is not None and initial_guess is None:
            args["x0"] = np.clip(self._last["x"], lbx, ubx)
            args["lam_x0"] = self._last["lam_x"]
            args["lam_g0"] = self._last["lam_g"]
        else:
            if warm and self._last is not None:  # the shifted warm start: the guess with the last multipliers
                args["lam_x0"] = self._last["lam_x"]
                args["lam_g0"] = self._last["lam_g"]
            if initial_guess is None:
                initial_guess, face = surface_dig(pile, start, duration, self.bucket, soil.phi, self.options.rho_margin)
            elif isinstance(initial_guess, Plan) and "face" in initial_guess.raw:
                face = initial_guess.raw["face"]
            args["x0"] = np.clip(self._guess_vector(initial_guess, pile, start, h), lbx, ubx)
        return face

    def reset_warm_start(self) -> None:
        """Forget the previous solution."""
        self._last = None

    def warm_start_from(self, other: TrajectoryOptimizer) -> None:
        """Continue (``solve(..., warm=True)``) from ``other``'s last solution, primal and dual (an optimizer
        of the same NLP with another solver, e.g. the MPC's IPOPT fallback)."""
        if other.intervals != self.intervals or other._layout["ng"] != self._layout["ng"]:
            raise PlanningError("warm_start_from needs an optimizer of the same NLP")
        self._last = None if other._last is None else {k: v.copy() for k, v in other._last.items()}

    def predict(self, soil: SoilParams | str | dict, pile: Pile, path: BucketPath, start_fill: float = 0.0) -> dict:
        """CasADi-model forces and energy along any path (for comparing with the NumPy model)."""
        soil = as_soil(soil)
        grid = self.options.surface
        windows = grid.window_parameters(grid.parameters(pile, float(path.x[0])), path.x)
        fill = pile.carve(path.x, path.z, self.bucket.width, self.bucket.capacity, start_fill).fill_history
        f = self._functions["forces"].map(len(path))
        velocity = [v[None, :] for v in path.velocity()[:2]] if self.options.force_model == "fee-learned" else []
        ft, fn = f(np.asarray(path.x)[None, :], np.asarray(path.z)[None, :], np.asarray(path.blade_angle)[None, :],
                   fill[None, :], soil_vector(soil, self.bucket), windows.T, *velocity)
        return {"F_T": np.array(ft).ravel(), "F_N": np.array(fn).ravel(), "fill": fill}

    # ------------------------------------------------------------------ internals
    def _parameters(self, soil: SoilParams, pile: Pile, start: StartState, h: float, lam: float,
                    windows: np.ndarray) -> np.ndarray:
        return np.concatenate([[start.x, start.z, start.blade_angle, start.fill, start.vx, start.vz, start.omega,
                                h, lam], soil_vector(soil, self.bucket), windows.ravel()])

    def _node_x(self, w: np.ndarray) -> np.ndarray:
        """Tip x of every node of the decision vector ``w`` [m]."""
        return w[0: 4 * (self.intervals + 1): 4]

    def _windows(self, pile: Pile, start: StartState, w: np.ndarray) -> np.ndarray:
        """Surface windows ``(N + 1, window_size)`` around the node positions of the decision vector ``w``."""
        grid = self.options.surface
        return grid.window_parameters(grid.parameters(pile, start.x), self._node_x(w))

    def _outside_windows(self, windows: np.ndarray, w: np.ndarray) -> bool:
        """Whether a node of ``w`` (with its slope chord) left the range its window reproduces."""
        lo, hi = self.options.surface.window_range(windows)
        node_x = self._node_x(w)
        return bool(np.any(node_x - DEFAULT_SLOPE_WINDOW < lo) or np.any(node_x + DEFAULT_SLOPE_WINDOW > hi))

    def _bounds(self, pile: Pile, start: StartState) -> tuple[np.ndarray, np.ndarray]:
        n = self.intervals
        ld, opt = self.loader, self.options
        heights = pile.heights
        z_lo = min(float(heights.min()), start.z)
        z_hi = max(float(heights.max()) + opt.lift_headroom, start.z)
        a_lo, a_hi = opt.blade_angle_limits
        a_lo, a_hi = min(a_lo, start.blade_angle), max(a_hi, start.blade_angle)
        x_lo = start.x - 1e-6
        x_hi = start.x + ld.max_speed * 60.0
        cap = self.bucket.capacity * opt.fill_limit
        lo_state = np.array([x_lo, z_lo, a_lo, 0.0])
        hi_state = np.array([x_hi, z_hi, a_hi, cap])
        lbx = np.concatenate([np.tile(lo_state, n + 1), np.tile([0.0, -ld.max_speed, -ld.max_tilt_rate], n)])
        ubx = np.concatenate([np.tile(hi_state, n + 1), np.tile([ld.max_speed, ld.max_speed, ld.max_tilt_rate], n)])
        first = np.array([start.x, start.z, start.blade_angle, start.fill])
        ubx[4 * 1 + 3::4][: n] = np.maximum(cap, start.fill)
        lbx[:4] = first
        ubx[:4] = first
        return lbx, ubx

    def _constraint_bounds(self, soil: SoilParams, min_fill: float, min_kept: float = 0.0
                           ) -> tuple[np.ndarray, np.ndarray]:
        lay = self._layout
        lbg = np.zeros(lay["ng"])
        ubg = np.zeros(lay["ng"])
        ubg[lay["ineq"]] = np.inf
        lbg[lay["fill_end"]] = min_fill
        ubg[lay["fill_end"]] = np.inf
        if "kept_end" in lay:
            lbg[lay["kept_end"]] = min_kept
            ubg[lay["kept_end"]] = np.inf
        return lbg, ubg

    def _guess_vector(self, guess: Plan | BucketPath, pile: Pile, start: StartState, h: float) -> np.ndarray:
        n = self.intervals
        t_nodes = np.arange(n + 1) * h
        if not isinstance(guess, (Plan, BucketPath)):
            raise PlanningError(f"initial_guess must be a Plan or a BucketPath, got {type(guess).__name__}")
        src_t = guess.t - guess.t[0]
        x, z, th = guess.x, guess.z, guess.blade_angle
        scale = src_t[-1] / t_nodes[-1] if t_nodes[-1] > 0 else 1.0
        ts = t_nodes * scale
        gx = np.maximum.accumulate(np.interp(ts, src_t, x))
        gz = np.interp(ts, src_t, z)
        gt = np.interp(ts, src_t, th)
        gx[0], gz[0], gt[0] = start.x, start.z, start.blade_angle
        gx = np.maximum.accumulate(gx)
        fill = pile.carve(gx, gz, self.bucket.width, self.bucket.capacity, min(start.fill, self.bucket.capacity))
        gv = fill.fill_history
        states = np.column_stack([gx, gz, gt, gv]).ravel()
        controls = np.column_stack([np.diff(gx) / h, np.diff(gz) / h, np.diff(gt) / h]).ravel()
        return np.concatenate([states, controls])

    def _plan_from(self, w: np.ndarray, p: np.ndarray, h: float, start: StartState, stats: dict, elapsed: float,
                   objective: float) -> Plan:
        n = self.intervals
        states = w[: 4 * (n + 1)].reshape(n + 1, 4)
        controls = w[4 * (n + 1):].reshape(n, 3)
        ft, fn, energy = self._functions["outputs"](w, p)
        t = np.arange(n + 1) * h
        status = str(stats.get("return_status", "unknown"))
        raw: dict[str, Any] = {"start": start, "h": h, "primal_infeasibility": _final_infeasibility(stats)}
        if "kept" in self._functions:  # the kept objective's terms as the NLP sees them (planner.kept)
            kept, lift, total, per_kept = (float(v) for v in self._functions["kept"](w, p))
            raw["kept_terms"] = {"kept": kept, "lift_energy": lift, "energy": total, "per_kept": per_kept}
        return Plan(t, states[:, 0].copy(), states[:, 1].copy(), states[:, 2].copy(), states[:, 3].copy(),
                    controls[:, 0].copy(), controls[:, 1].copy(), controls[:, 2].copy(),
                    np.array(ft).ravel(), np.array(fn).ravel(), float(energy), bool(stats.get("success", False)),
                    status, int(stats.get("iter_count", -1)), elapsed, objective, raw=raw)


class _Watch:
    """The iteration monitor's watch during one solve: every ``every`` iterations, the iterate as a Plan
    to ``checkpoint``; an exception it raises stops the solve and is re-raised after it."""

    def __init__(self, optimizer: TrajectoryOptimizer, checkpoint: Callable[[Plan], bool], every: int,
                 p: np.ndarray, h: float, start: StartState, face: float, offset: int, started: float) -> None:
        self.optimizer, self.checkpoint, self.every = optimizer, checkpoint, max(int(every), 1)
        self.started = started  # perf_counter() when the solve began: an iterate's solve_time counts from it
        self.p, self.h, self.start, self.face = p, h, start, face
        self.calls, self.offset = 0, offset
        self.error: BaseException | None = None

    def __call__(self, w: np.ndarray) -> bool:
        k = self.calls  # IPOPT calls back at iteration 0 (the initial point), 1, 2, ...
        self.calls += 1
        if k == 0 or k % self.every:
            return False
        it = self.offset + k
        try:
            plan = self.optimizer._plan_from(w, self.p, self.h, self.start,
                                             {"return_status": f"iterate {it}", "iter_count": it, "success": False},
                                             time.perf_counter() - self.started, math.nan)
            plan.raw["face"] = self.face
            return bool(self.checkpoint(plan))
        except Exception as exc:  # noqa: BLE001 - re-raised after the solve
            self.error = exc
            return True


def _violation(w: np.ndarray, g: np.ndarray, args: dict[str, Any]) -> float:
    """Largest violation of the bounds and constraints by ``w`` and its constraint values ``g`` (unscaled; NaN if
    either is not finite)."""
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(w))):
        return math.nan
    return max(float(np.max(args["lbg"] - g)), float(np.max(g - args["ubg"])),
               float(np.max(args["lbx"] - w)), float(np.max(w - args["ubx"])), 0.0)


def _final_infeasibility(stats: dict) -> float:
    """IPOPT's primal infeasibility (largest constraint violation, scaled) at its last iterate, or the largest
    violation that :meth:`TrajectoryOptimizer.solve` computed for another solver; NaN if unknown."""
    if "primal_infeasibility" in stats:
        return float(stats["primal_infeasibility"])
    history = stats.get("iterations") or {}
    values = history.get("inf_pr") or []
    return float(values[-1]) if len(values) else math.nan
