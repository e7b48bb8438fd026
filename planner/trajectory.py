"""Full-cycle trajectory optimisation of the bucket path (CasADi + IPOPT).

Direct transcription on ``N`` intervals of length ``h`` (a parameter, so a
solver serves any cycle duration). States at the nodes ``k = 0..N``: tip
position ``x, z`` [m], blade angle ``theta`` [rad] and bucket fill ``V``
[m^3]; controls on the intervals: tip velocity ``v_x, v_z`` [m/s] and tilt
rate ``omega`` [rad/s], constant over an interval (so the tip path is
piecewise linear and the env's kinematics reproduce it exactly up to the
acceleration ramps).

* Fill: the tip moves forward only (``v_x >= 0``), so the soil it removes
  over an interval is the area between the start-of-cycle surface and the
  segment, ``w * dx * max(z_s - z, 0)`` averaged over its end nodes (the
  carving of :meth:`Pile.carve` for a forward path), and the bucket holds at
  most its capacity.
* Forces: :func:`~wheelloader.planner.casadi_model.casadi_forces` (eqs 1,
  10-17) at every node with the node's fill as payload, as the env does.
* Energy: the env's bookkeeping, ``max(0, F_T ds_t + F_N ds_n)`` plus
  ``max(0, W_load dz)`` per interval (smooth max).
* Objective: ``- V_N / capacity + lambda * E / 1 kJ + mu * sum |du|^2``
  (fill against energy; ``mu`` a small smoothing weight), optionally with a
  lower bound on the final fill ("least energy for a fill target").
* Constraints: dynamics; velocity and acceleration limits of the loader;
  blade-angle and workspace limits; ``F_T <= margin * max_push_force`` and
  ``F_N <= margin * max_lift_force``; the validity domain where the tip is in
  soil, ``rho_min + rho_margin <= rho <= pi - eps1 - eps2 - delta - phi -
  rho_margin`` and ``|alpha| <= alpha_max - rho_margin`` (relaxed by :data:`VALIDITY_RELAX` times the height above the
  surface, so it binds only in soil); the start pose and velocity; and the end out of the pile,
  ``z_N >= z_s(x_N) + end_clearance``, while past the face every earlier node
  stays at most ``stay_clearance`` above the surface (no hop out and back in).

The NLP is built once per (intervals, bucket, loader, options) and cached;
each call only passes new parameters, bounds and the initial guess.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from wheelloader.envs.bookkeeping import step_work
from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    GRAVITY,
    Bucket,
    BucketPath,
    Loader,
    Pile,
    SoilParams,
    as_soil,
)
from wheelloader.estimator.errors import PlanningError
from wheelloader.estimator.kinematics import DEFAULT_SLOPE_WINDOW

from .casadi_model import casadi_forces, smooth_pos, soil_vector
from .surface import SurfaceGrid


@dataclass(frozen=True)
class PlannerOptions:
    """Settings of the trajectory optimiser (SI units).

    Parameters
    ----------
    intervals : int
        Number of intervals N of the transcription (default 40).
    energy_weight : float
        lambda: cost per kJ of energy, in bucket-fills (default 0.02/kJ: 1 kJ
        is worth 2 % of a bucket).
    smoothing_weight : float
        mu: weight of the squared control changes (default 1e-3).
    force_margin : float
        Fraction of the loader's force limits the plan may use (default 0.85).
    rho_margin : float
        Margin kept from the validity domain's angle limits [rad] (default 5 deg: the smooth surface's
        chord slope differs from the pile's by up to ~3 deg next to carved kinks).
    end_clearance : float
        Height of the final tip pose above the surface [m] (default 0.05 m).
    max_tilt_acceleration : float
        Tilt acceleration limit [rad/s^2] (default 4, the env's).
    blade_angle_limits : tuple of float
        Blade-angle range [rad] (default -45 to 75 deg, the env's).
    lift_headroom : float
        How far above the highest surface point the tip may go [m] (default 1 m).
    fill_limit : float
        Largest planned fill as a fraction of the bucket capacity (default 0.95: the
        planner's fill model is the midpoint rule on a smoothed surface; the margin keeps
        the real carving from spilling).
    stay_clearance : float
        Past the face, the tip stays at most this high above the surface until the last
        interval [m] (default 0.01 m; the env ends a cycle at 0.02 m).
    max_iter : int
        IPOPT iteration limit (default 300).
    max_wall_time : float, optional
        IPOPT wall-time limit per solve [s] (default None: none). A solve stopped by it returns
        its last iterate (status ``Maximum_WallTime_Exceeded``): check it with
        :func:`~wheelloader.planner.verify_plan` before use.
    ipopt_warm_start : bool
        Build IPOPT with its warm-start settings (``warm_start_init_point``, ``mu_init`` 1e-4): a
        ``solve(..., warm=True)`` then starts from the previous primal *and* dual solution. For MPC,
        where successive problems differ little (default False).
    tolerance : float
        IPOPT tolerance (default 1e-4; the objective is O(1)).
    surface : SurfaceGrid
        Layout of the smooth surface.
    """

    intervals: int = 40
    energy_weight: float = 0.02
    smoothing_weight: float = 1e-3
    force_margin: float = 0.85
    rho_margin: float = math.radians(5.0)
    end_clearance: float = 0.05
    max_tilt_acceleration: float = 4.0
    blade_angle_limits: tuple[float, float] = (math.radians(-45.0), math.radians(75.0))
    lift_headroom: float = 1.0
    fill_limit: float = 0.95
    stay_clearance: float = 0.01
    max_iter: int = 300
    max_wall_time: float | None = None
    ipopt_warm_start: bool = False
    tolerance: float = 1e-4
    surface: SurfaceGrid = field(default_factory=SurfaceGrid)

    def __post_init__(self) -> None:
        if not (isinstance(self.intervals, int) and 4 <= self.intervals <= 400):
            raise PlanningError(f"PlannerOptions.intervals must be an integer in [4, 400], got {self.intervals!r}")
        for name in ("energy_weight", "smoothing_weight", "rho_margin", "end_clearance", "lift_headroom"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise PlanningError(f"PlannerOptions.{name} must be a finite number >= 0, got {value!r}")
        if not (0.0 < self.fill_limit <= 1.0):
            raise PlanningError(f"PlannerOptions.fill_limit must be in (0, 1], got {self.fill_limit!r}")
        if not (0.0 < self.force_margin <= 1.0):
            raise PlanningError(f"PlannerOptions.force_margin must be in (0, 1], got {self.force_margin!r}")
        if not self.max_tilt_acceleration > 0.0:
            raise PlanningError("PlannerOptions.max_tilt_acceleration must be > 0 rad/s^2")
        lo, hi = self.blade_angle_limits
        if not (-math.pi / 2 < lo < hi < math.pi / 2):
            raise PlanningError(f"PlannerOptions.blade_angle_limits must be (low, high) in (-pi/2, pi/2) rad, "
                                f"got {self.blade_angle_limits!r}")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1) or not self.tolerance > 0.0:
            raise PlanningError("PlannerOptions.max_iter must be a positive integer and tolerance > 0")
        if self.max_wall_time is not None and not (isinstance(self.max_wall_time, (int, float))
                                                   and math.isfinite(self.max_wall_time) and self.max_wall_time > 0):
            raise PlanningError(f"PlannerOptions.max_wall_time must be None or a number of seconds > 0, "
                                f"got {self.max_wall_time!r}")


@dataclass(frozen=True)
class StartState:
    """Where a plan starts: tip pose, velocity and fill.

    Parameters
    ----------
    x, z, blade_angle : float
        Tip pose [m, m, rad].
    vx, vz, omega : float
        Tip velocity and tilt rate [m/s, m/s, rad/s] (default at rest).
    fill : float
        Soil already in the bucket [m^3] (default 0).
    """

    x: float
    z: float
    blade_angle: float
    vx: float = 0.0
    vz: float = 0.0
    omega: float = 0.0
    fill: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "z", "blade_angle", "vx", "vz", "omega", "fill"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise PlanningError(f"StartState.{name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.fill < 0.0:
            raise PlanningError(f"StartState.fill must be >= 0 m^3, got {self.fill!r}")

    @classmethod
    def from_observation(cls, obs: np.ndarray, capacity: float) -> StartState:
        """From a ``BucketLoadingEnv`` observation (indices 0-5 pose and rates, 9 fill fraction)."""
        o = [float(v) for v in np.asarray(obs, dtype=float).ravel()[:10]]
        return cls(o[0], o[1], o[2], o[3], o[4], o[5], max(o[9], 0.0) * capacity)


@dataclass(frozen=True, eq=False)
class Plan:
    """A planned bucket path with what the CasADi model predicts along it.

    Attributes
    ----------
    t, x, z, blade_angle, fill : numpy.ndarray
        Node times [s] and states (N + 1 values).
    vx, vz, omega : numpy.ndarray
        Interval controls (N values) [m/s, m/s, rad/s].
    tangential, normal : numpy.ndarray
        Predicted F_T, F_N at the nodes [N] (node 0: at the start pose, empty of new soil).
    energy : float
        Predicted energy of the cycle [J].
    success : bool
        Whether IPOPT reported success.
    status : str
        IPOPT's return status.
    iterations : int
        IPOPT iterations.
    solve_time : float
        Wall time of the solver call [s].
    objective : float
        Final objective value.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    blade_angle: np.ndarray
    fill: np.ndarray
    vx: np.ndarray
    vz: np.ndarray
    omega: np.ndarray
    tangential: np.ndarray
    normal: np.ndarray
    energy: float
    success: bool
    status: str
    iterations: int
    solve_time: float
    objective: float
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def duration(self) -> float:
        """Planned duration [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def final_fill(self) -> float:
        """Predicted fill at the end [m^3]."""
        return float(self.fill[-1])

    def path(self, rate: float = 60.0, name: str = "planned") -> BucketPath:
        """The plan sampled at ``rate`` [Hz] (linear between nodes: the controls are piecewise constant)."""
        if not rate > 0.0:
            raise PlanningError(f"rate must be > 0 Hz, got {rate!r}")
        count = int(math.floor(self.duration * rate + 1e-9)) + 1
        t = self.t[0] + np.arange(count) / rate
        if t[-1] < self.t[-1] - 1e-9:
            t = np.append(t, self.t[-1])
        return BucketPath(t - self.t[0], np.interp(t, self.t, self.x), np.interp(t, self.t, self.z),
                          np.interp(t, self.t, self.blade_angle), name)


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
        self._solver, self._functions, self._layout = _build(self.bucket, self.loader, self.options)
        self._last: dict[str, np.ndarray] | None = None

    # ------------------------------------------------------------------ API
    @property
    def intervals(self) -> int:
        """N."""
        return self.options.intervals

    def solve(self, soil: SoilParams | str | dict, pile: Pile, start: StartState, duration: float, *,
              energy_weight: float | None = None, min_fill: float = 0.0, initial_guess: Plan | BucketPath | None = None,
              warm: bool = False, reference: BucketPath | None = None, reference_weight: float = 0.0) -> Plan:
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
            else a straight dig along the surface.
        warm : bool
            Start from the previous solution (and its multipliers) if there is one.
        reference : BucketPath, optional
            A path to stay close to (MPC: the plan being executed), weighted by
            ``reference_weight`` [1/m^2] on the mean squared tip-position distance.

        Returns
        -------
        Plan
            Always returned; check ``plan.success`` (and :func:`~wheelloader.planner.verify_plan`).
        """
        soil = as_soil(soil)
        if not isinstance(start, StartState):
            raise PlanningError(f"start must be a StartState, got {type(start).__name__}")
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and 0.2 <= duration <= 60.0):
            raise PlanningError(f"duration must be between 0.2 and 60 s, got {duration!r}")
        lam = self.options.energy_weight if energy_weight is None else energy_weight
        if not (isinstance(lam, (int, float)) and math.isfinite(lam) and lam >= 0.0):
            raise PlanningError(f"energy_weight must be a finite number >= 0, got {lam!r}")
        cap = self.bucket.capacity
        if not (0.0 <= min_fill <= cap):
            raise PlanningError(f"min_fill must be between 0 and the capacity {cap} m^3, got {min_fill!r}")
        if start.fill > cap * (1 + 1e-9):
            raise PlanningError(f"start fill {start.fill} m^3 exceeds the bucket capacity {cap} m^3")
        n = self.intervals
        h = float(duration) / n
        if not (math.isfinite(reference_weight) and reference_weight >= 0.0):
            raise PlanningError(f"reference_weight must be a finite number >= 0, got {reference_weight!r}")
        ref = np.zeros((n + 1, 2))
        if reference is not None and reference_weight > 0.0:
            ts = np.arange(n + 1) * h
            rt = reference.t - reference.t[0]
            ref = np.column_stack([np.interp(ts, rt, reference.x), np.interp(ts, rt, reference.z)])
        else:
            reference_weight = 0.0
        lbx, ubx = self._bounds(pile, start)
        lbg, ubg = self._constraint_bounds(soil, min_fill)
        args: dict[str, Any] = {"lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}
        if warm and self._last is not None and initial_guess is None:
            args["x0"] = np.clip(self._last["x"], lbx, ubx)
            args["lam_x0"] = self._last["lam_x"]
            args["lam_g0"] = self._last["lam_g"]
        else:
            guess = initial_guess if initial_guess is not None else straight_dig(pile, start, duration, self.bucket)
            args["x0"] = np.clip(self._guess_vector(guess, pile, start, h), lbx, ubx)
        tail = np.concatenate([ref.ravel(), [reference_weight], [face_position(pile, start)]])
        tic = time.perf_counter()
        # each node sees the surface through a window placed around its start position; a node that moves
        # out of its window's range is re-solved once, from where IPOPT stopped, with re-centred windows
        # (not after the wall-time limit: the NumPy check judges that iterate on the real pile)
        iterations = 0
        for attempt in range(2):
            windows = self._windows(pile, start, args["x0"])
            args["p"] = p = np.concatenate([self._parameters(soil, pile, start, h, lam, windows), tail])
            sol = self._solver(**args)
            stats = dict(self._solver.stats())
            iterations += int(stats.get("iter_count", 0))
            w = np.array(sol["x"]).ravel()
            self._last = {"x": w, "lam_x": np.array(sol["lam_x"]).ravel(), "lam_g": np.array(sol["lam_g"]).ravel()}
            out_of_time = stats.get("return_status") == "Maximum_WallTime_Exceeded"
            if attempt == 1 or out_of_time or not self._outside_windows(windows, w):
                break
            args.update(x0=w, lam_x0=self._last["lam_x"], lam_g0=self._last["lam_g"])
        elapsed = time.perf_counter() - tic
        stats["iter_count"] = iterations
        return self._plan_from(w, p, h, start, stats, elapsed, float(sol["f"]))

    def reset_warm_start(self) -> None:
        """Forget the previous solution."""
        self._last = None

    def predict(self, soil: SoilParams | str | dict, pile: Pile, path: BucketPath, start_fill: float = 0.0) -> dict:
        """CasADi-model forces and energy along any path (for comparing with the NumPy model)."""
        soil = as_soil(soil)
        grid = self.options.surface
        windows = grid.window_parameters(grid.parameters(pile, float(path.x[0])), path.x)
        fill = pile.carve(path.x, path.z, self.bucket.width, self.bucket.capacity, start_fill).fill_history
        f = self._functions["forces"].map(len(path))
        ft, fn = f(np.asarray(path.x)[None, :], np.asarray(path.z)[None, :], np.asarray(path.blade_angle)[None, :],
                   fill[None, :], soil_vector(soil, self.bucket), windows.T)
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

    def _constraint_bounds(self, soil: SoilParams, min_fill: float) -> tuple[np.ndarray, np.ndarray]:
        lay = self._layout
        lbg = np.zeros(lay["ng"])
        ubg = np.zeros(lay["ng"])
        ubg[lay["ineq"]] = np.inf
        lbg[lay["fill_end"]] = min_fill
        ubg[lay["fill_end"]] = np.inf
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
        return Plan(t, states[:, 0].copy(), states[:, 1].copy(), states[:, 2].copy(), states[:, 3].copy(),
                    controls[:, 0].copy(), controls[:, 1].copy(), controls[:, 2].copy(),
                    np.array(ft).ravel(), np.array(fn).ravel(), float(energy), bool(stats.get("success", False)),
                    status, int(stats.get("iter_count", -1)), elapsed, objective,
                    raw={"start": start, "h": h, "primal_infeasibility": _final_infeasibility(stats)})


def _final_infeasibility(stats: dict) -> float:
    """IPOPT's primal infeasibility (largest constraint violation, scaled) at its last iterate; NaN if unknown."""
    history = stats.get("iterations") or {}
    values = history.get("inf_pr") or []
    return float(values[-1]) if len(values) else math.nan


def first_rise(pile: Pile, start: StartState, rise: float, step: float = 0.005, reach: float = 4.0) -> float | None:
    """x where the surface first lies more than ``rise`` above the start height, searching ``reach`` metres
    ahead of ``start`` in ``step`` increments [m]; None when it never does."""
    xs = start.x + np.arange(0.0, reach, step)
    rising = np.nonzero(np.asarray(pile.surface_height(xs)) > start.z + rise)[0]
    return float(xs[rising[0]]) if rising.size else None


def face_position(pile: Pile, start: StartState) -> float:
    """x where the surface first rises 3 cm above the start height ahead of ``start`` [m] (the face)."""
    x_face = first_rise(pile, start, 0.03)
    return start.x if x_face is None else x_face


def straight_dig(pile: Pile, start: StartState, duration: float, bucket: Bucket) -> BucketPath:
    """A simple initial guess: approach the face at ground level, dig ~15 cm under the surface, rise out.

    The approach ends where the surface first rises 5 cm above the start height; the dig
    advances until the bucket would be full (by carving), then the tip rises out of the pile.
    """
    x_face = first_rise(pile, start, 0.05)
    x_face = start.x + 0.5 if x_face is None else x_face
    depth = 0.15
    x_dig = np.linspace(x_face, x_face + 3.0, 301)
    z_dig = np.maximum(np.asarray(pile.surface_height(x_dig)) - depth, start.z)
    carve = pile.carve(np.concatenate([[start.x], x_dig]), np.concatenate([[start.z], z_dig]), bucket.width,
                       bucket.capacity, min(start.fill, bucket.capacity))
    full = np.nonzero(carve.fill_history[1:] >= 0.95 * bucket.capacity)[0]
    end = int(full[0]) if full.size else len(x_dig) - 1
    x_end = x_dig[end]
    z_top = float(pile.surface_height(x_end + 0.3)) + 0.1
    px = np.array([start.x, x_face, x_end, x_end + 0.3])
    pz = np.array([start.z, z_dig[0], z_dig[end], z_top])
    seg = np.hypot(np.diff(px), np.diff(pz))
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, duration, 121)
    s = t / duration * arc[-1]
    theta = np.interp(t / duration, [0.0, 0.6, 1.0], [start.blade_angle, start.blade_angle, math.radians(30.0)])
    return BucketPath(t, np.interp(s, arc, px), np.interp(s, arc, pz), theta, name="straight dig")


# ---------------------------------------------------------------------- NLP construction
_CACHE: dict[tuple, tuple] = {}
#: How fast the validity-domain limits on rho relax above the surface [rad/m]: the limits bind in soil
#: and fade out within centimetres above it (a product ``depth * (rho - limit) >= 0`` would be degenerate
#: out of soil and blow up IPOPT's multipliers).
VALIDITY_RELAX = 30.0


def _smooth_work(v):
    """Smooth ``max(v, 0)`` of a step's work [J] (1 J wide)."""
    return smooth_pos(v, 1.0)


def _build(bucket: Bucket, loader: Loader, options: PlannerOptions):
    key = (bucket, loader, options)
    if key not in _CACHE:
        _CACHE[key] = _build_nlp(bucket, loader, options)
    return _CACHE[key]


def _build_nlp(bucket: Bucket, loader: Loader, options: PlannerOptions):
    n = options.intervals
    grid = options.surface
    # parameters
    p_start = ca.SX.sym("start", 4)
    p_vel0 = ca.SX.sym("vel0", 3)
    p_h = ca.SX.sym("h")
    p_lam = ca.SX.sym("lam")
    p_soil = ca.SX.sym("soil", 7)
    p_surf = ca.SX.sym("surf", grid.window_size, n + 1)  # one surface window per node
    p_ref = ca.SX.sym("ref", 2, n + 1)
    p_wref = ca.SX.sym("wref")
    p_face = ca.SX.sym("face")
    p = ca.vertcat(p_start, p_vel0, p_h, p_lam, p_soil, ca.vec(p_surf), ca.vec(p_ref), p_wref, p_face)
    # single-node force function (also used by predict)
    xs, zs, ths, vs = ca.SX.sym("x"), ca.SX.sym("z"), ca.SX.sym("th"), ca.SX.sym("V")
    p_win = ca.SX.sym("window", grid.window_size)
    alpha = grid.window_slope_angle(xs, p_win)
    vertical = grid.window_height(xs, p_win) - zs
    w_load = p_soil[0] * GRAVITY * vs
    out = casadi_forces(p_soil, vertical, alpha - ths, alpha, w_load, bucket, DEFAULT_OPTIONS)
    rho = alpha - ths
    forces = ca.Function("forces", [xs, zs, ths, vs, p_soil, p_win], [out["F_T"], out["F_N"]])
    node = ca.Function("node", [xs, zs, ths, vs, p_soil, p_win], [out["F_T"], out["F_N"], rho, vertical, alpha])
    # decision variables
    X = ca.SX.sym("X", 4, n + 1)
    U = ca.SX.sym("U", 3, n)
    w = ca.vertcat(ca.vec(X), ca.vec(U))
    h = p_h
    g_eq, g_ineq = [], []
    energy = 0.0
    smooth = 0.0
    ft_all, fn_all = [], []
    ft0, fn0, _, vertical_prev, _ = node(X[0, 0], X[1, 0], X[2, 0], X[3, 0], p_soil, p_surf[:, 0])
    ft_all.append(ft0)
    fn_all.append(fn0)
    phi, delta = p_soil[3], p_soil[4]
    rho_lo = DEFAULT_OPTIONS.rho_min + options.rho_margin
    rho_hi = math.pi - DEFAULT_OPTIONS.eps1 - DEFAULT_OPTIONS.eps2 - delta - phi - options.rho_margin
    alpha_hi = DEFAULT_OPTIONS.alpha_max - options.rho_margin
    f_push = options.force_margin * loader.max_push_force
    f_lift = options.force_margin * loader.max_lift_force
    acc = loader.max_acceleration
    tilt_acc = options.max_tilt_acceleration
    prev_u = p_vel0
    for k in range(n):
        xk, zk, tk, vk = X[0, k], X[1, k], X[2, k], X[3, k]
        xn, zn, tn, vn = X[0, k + 1], X[1, k + 1], X[2, k + 1], X[3, k + 1]
        u = U[:, k]
        dx, dz = h * u[0], h * u[1]
        # kinematics (exact for piecewise-constant velocity)
        g_eq += [xn - xk - dx, zn - zk - dz, tn - tk - h * u[2]]
        # forces at the new node (and its depth below the surface)
        f_t, f_n, rho_n, vertical, alpha_n = node(xn, zn, tn, vn, p_soil, p_surf[:, k + 1])
        # fill: area between the start surface and the segment (trapezoid rule on the node depths),
        # capped by the bounds on V
        removed = bucket.width * dx * smooth_pos(0.5 * (vertical_prev + vertical), 1e-3)
        vertical_prev = vertical
        g_eq.append(vn - vk - removed)
        # acceleration limits
        du = u - prev_u
        g_ineq += [acc * h - du[0], acc * h + du[0], acc * h - du[1], acc * h + du[1],
                   tilt_acc * h - du[2], tilt_acc * h + du[2]]
        smooth = smooth + ca.sumsqr(du / ca.vertcat(acc, acc, tilt_acc))
        prev_u = u
        # force limits and validity domain at the new node
        ft_all.append(f_t)
        fn_all.append(f_n)
        slack = VALIDITY_RELAX * smooth_pos(-vertical, 1e-3)
        if k < n - 1:
            # once past the face the tip stays in or just above the soil until the last interval: the env
            # ends a cycle as soon as the tip has been in soil and is more than its exit clearance above
            # the surface; before the face (the approach over the ground) the constraint is off
            before_face = 0.5 * (1.0 + ca.tanh((p_face - xn) / 0.02))
            g_ineq.append(options.stay_clearance + vertical + 10.0 * before_face)
        g_ineq += [1.0 - f_t / f_push, 1.0 - f_n / f_lift, rho_n - rho_lo + slack, rho_hi - rho_n + slack,
                   alpha_hi - alpha_n + slack, alpha_n + alpha_hi + slack]
        # energy: the env's bookkeeping, with a smooth positive part (1 J wide)
        e_soil, e_payload = step_work(f_t, f_n, dx, dz, tn, p_soil[0] * GRAVITY * vn, cos=ca.cos, sin=ca.sin,
                                      pos=_smooth_work)
        energy = energy + e_soil + e_payload
    # end out of the pile
    end_clear = X[1, n] - grid.window_height(X[0, n], p_surf[:, n]) - options.end_clearance
    g_ineq.append(end_clear)
    fill_end = X[3, n]
    g = ca.vertcat(*g_eq, *g_ineq, fill_end)
    n_eq, n_ineq = len(g_eq), len(g_ineq)
    tracking = ca.sumsqr(X[0:2, 1:] - p_ref[:, 1:]) / n
    objective = (-X[3, n] / bucket.capacity + p_lam * energy / 1000.0
                 + options.smoothing_weight * smooth / n + p_wref * tracking)
    nlp = {"x": w, "p": p, "f": objective, "g": g}
    solver_opts = {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
        "ipopt.max_iter": options.max_iter, "ipopt.tol": options.tolerance,
        "ipopt.acceptable_tol": 1e-3, "ipopt.acceptable_iter": 5,
        "ipopt.mu_strategy": "adaptive", "error_on_fail": False,
    }
    if options.max_wall_time is not None:
        solver_opts["ipopt.max_wall_time"] = float(options.max_wall_time)
    if options.ipopt_warm_start:
        solver_opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                            "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
    solver = ca.nlpsol("bucket_path", "ipopt", nlp, solver_opts)
    outputs = ca.Function("outputs", [w, p], [ca.vertcat(*ft_all), ca.vertcat(*fn_all), energy])
    layout = {"ng": n_eq + n_ineq + 1, "ineq": slice(n_eq, n_eq + n_ineq), "fill_end": n_eq + n_ineq}
    return solver, {"forces": forces, "outputs": outputs}, layout
