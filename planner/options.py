"""Settings of the trajectory optimiser and the start state of a plan."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from wheelloader.estimator import DEFAULT_OPTIONS, ModelOptions, PayloadOptions, PlanningError
from wheelloader.estimator.checks import check_choice, check_finite, check_int, check_range
from wheelloader.estimator.force_models import (
    DEFAULT_FORCE_MODEL,
    DEFAULT_PAYLOAD,
    FORCE_MODELS,
    PAYLOAD_MODELS,
    check_force_model,
    model_options_for,
)
from wheelloader.estimator.payload import removed_volume

from .surface import SurfaceGrid

__all__ = ["OBJECTIVES", "QP_SOLVERS", "SOLVERS", "PlannerOptions", "StartState"]

#: The planner's objectives (:attr:`PlannerOptions.objective`).
OBJECTIVES: tuple[str, ...] = ("fill_energy", "kept_per_energy")
#: The NLP solvers (:attr:`PlannerOptions.solver`): IPOPT (interior point) or CasADi's ``sqpmethod``.
SOLVERS: tuple[str, ...] = ("ipopt", "sqp")
#: The QP solvers of ``solver="sqp"`` (:attr:`PlannerOptions.qp_solver`; CasADi conic plugins on dense QPs).
QP_SOLVERS: tuple[str, ...] = ("daqp", "qpoases", "osqp")


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
        Margin kept from the validity domain's angle limits [rad] (default 5 deg: next to carved kinks the
        smooth surface's chord slope differs from the pile's).
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
        interval [m] (default 0.005 m; the env ends a cycle at 0.02 m and the NumPy check, allowing 0.01 m
        for tracking, at 0.01 m).
    validity_band : float
        Height above the surface within which the validity-domain constraints still bind [m] (default 0.01 m;
        above it they fade out). The NLP's surface rounds the pile's kinks, so near a carved wall a tip the
        NLP sees just above the surface can be in soil on the pile.
    midpoints : bool
        Constrain forces and the validity domain at the midpoint of every interval too, and integrate the
        fill with Simpson's rule (default False).
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
    failure_angle : {"min_n_gamma", "min_weight_force"}
        How the planner's force model (the CasADi NLP and the NumPy check) picks beta*: the paper's rule
        (default) or the opt-in least weight force (:class:`~wheelloader.estimator.ModelOptions`).
    cut_angle : float, optional
        Opt-in cutting cone [rad]: deeper than ``cut_depth`` in soil, the tip's velocity stays within this
        angle of the blade direction, i.e. the blade cuts its way (the FEE's wedge forms ahead of a blade
        that advances along itself) instead of the bucket being pushed sideways or lifted through the soil
        on its floor, which the model does not describe (default None: off). The fixed Bezier path moves
        within 54 deg of its blade.
    cut_depth : float
        Depth below which the cutting cone binds [m] (default 0.05 m; above it the bucket may lift and curl
        out of the soil).
    heel_clearance : float, optional
        Opt-in: the heel of the bucket (the back end of its floor, ``floor_length`` behind the tip along the
        blade) stays at least this high above the surface [m] (default None: off; 0 keeps it out of the
        soil). The FEE describes the soil in front of the blade; a buried heel drags the floor and the back
        plate through soil the model does not see (the fixed Bezier path keeps its heel above the surface).
    end_blade_angle : float, optional
        Opt-in: the smallest blade angle at the end of the plan [rad] (default None: off). A bucket carries
        its load curled; the model's fill is the soil carved, whatever the bucket's tilt, so without it a
        plan may end tilted forward and, in a plant, lose what it carved (the fixed Bezier path ends at 45 deg).
    curl_out_intervals : int
        With ``end_blade_angle``: the last intervals, in which the bucket curls out of the pile: there the tip
        may leave the soil (``stay_clearance`` does not bind; default 0: the tip stays in or just above the
        soil until the last interval). With a heel kept out of the soil a bucket cannot curl to
        ``end_blade_angle`` in one interval while its tip is at the surface (at 45 deg its heel lies 0.32 m
        below the tip), so without them the NLP is infeasible on any pile; in the curl-out the bucket rises
        while it curls, its heel still above the surface. The env ends a cycle once the tip has left the
        soil, so there the curl-out is not tracked.
    descend_clearance : float, optional
        Opt-in: the tip moves down only while it is at most this high above the surface (or in soil) at the
        start of an interval [m] (default None: off). The force model has no force for a bucket coming down
        onto the pile from above on its floor: in the MPM plant a plan that rose to 0.86 m and came down onto
        the pile met a 143 kN peak, 2.4x the energy predicted (``docs/results/loop_mpm.md``). Digging down
        from the surface stays allowed.
    tolerance : float
        IPOPT tolerance (default 1e-4; the objective is O(1)); with ``solver="sqp"`` the SQP's primal and dual
        tolerances.
    solver : {"ipopt", "sqp"}
        The NLP solver (default ``"ipopt"``). ``"sqp"``: CasADi's ``sqpmethod`` with the exact Hessian of the
        Lagrangian, regularised to be convex (``convexify_strategy="regularize"``), one QP per iteration
        solved by ``qp_solver`` and a line search; with ``max_iter=1`` one QP per solve, the real-time iteration
        of :class:`~wheelloader.planner.MPCController` (which keeps IPOPT as its fallback). Its
        ``primal_infeasibility`` is the largest violation of the bounds and constraints (unscaled). Made for
        warm starts: from a converged IPOPT plan it converges to the same cost, from a cold guess it
        converges slowly (the regularised Hessian damps its steps; a full-cycle plan stays with IPOPT).
    qp_solver : {"daqp", "qpoases", "osqp"}
        The QP solver of ``solver="sqp"`` (default ``"daqp"``, the fastest in ``benchmarks/planner.py``).
    compiled : bool
        Evaluate the solver's derivatives (the Hessian of the Lagrangian, the Jacobian, with IPOPT also the
        objective's gradient) as C code compiled once per machine and cached on disk
        (:mod:`wheelloader.planner.codegen`; default False: CasADi's virtual machine). The same iterates; the
        compile takes about 30 s of CPU for the MPC's 12-interval SQP and a few minutes for a 40-interval
        IPOPT plan (:func:`~wheelloader.planner.codegen.compiled_by_key`, found again by the NLP cache's key, so
        a later process neither differentiates nor generates code). Without a C compiler, or when the compile
        fails, the virtual machine is used (a warning).
    objective : {"fill_energy", "kept_per_energy"}
        What the plan optimises: the carved fill against energy (default, ``-V/capacity + lambda E``), or the
        opt-in energy per m^3 of *kept* soil with the load lifted on to ``dump_height``
        (:mod:`wheelloader.planner.kept`): the payload model's kept fill of the carved volume, constrained to at
        least ``kept_target``.
    payload : PayloadOptions, optional
        The payload state of ``"kept_per_energy"`` and of the payload force models (default
        :data:`~wheelloader.estimator.DEFAULT_PAYLOAD`; under ``"fee-learned"`` the payload fitted with it).
    dump_height : float, optional
        The common height the load is lifted to [m] (default: the fixed Bezier path's end height,
        :func:`~wheelloader.planner.kept.dump_height`).
    kept_target : float, optional
        Least kept fill as a fraction of the nominal capacity (default None: the fixed Bezier path's kept fill on
        the same pile, :func:`~wheelloader.planner.kept.fixed_kept_fill`, as :func:`plan_next_cycle` sets it).
    kept_target_scale : float
        Factor on that least kept fill (default 1; in (0, 2]): e.g. 1.05 asks 5 % more kept soil than the fixed
        path keeps on the pile (the look-ahead's ``KEPT_CANDIDATES``, :mod:`wheelloader.planner.lookahead`).
    force_model : str
        The force model the plan is made and checked with, a name of :data:`~wheelloader.estimator.FORCE_MODELS`
        (as ``force_model=`` of :func:`~wheelloader.estimator.calibrate` and the env): ``"fee"`` (default, the
        paper's), ``"fee-payload"`` or ``"fee-learned"``: the NLP's state ``V`` stays the carved volume (the
        surcharge's fill), the
        fill of the objective, of ``min_fill`` and of the NumPy check is the payload's kept soil
        ``kept_volume(V)``, and its weight stays on the bucket as the tip leaves the soil
        (:func:`~wheelloader.planner.casadi_model.casadi_forces` ``carried_weight``; weight only: within an
        interval the plan's velocity is constant, so the inertia the env adds while it tracks the plan is not in
        the NLP); ``"fee-learned"`` adds the learned correction's CasADi twin at every node (the interval's speed;
        :func:`~wheelloader.planner.casadi_model.casadi_learned`).
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
    stay_clearance: float = 0.005
    validity_band: float = 0.01
    midpoints: bool = False
    max_iter: int = 300
    max_wall_time: float | None = None
    ipopt_warm_start: bool = False
    tolerance: float = 1e-4
    solver: str = "ipopt"
    qp_solver: str = "daqp"
    compiled: bool = False
    surface: SurfaceGrid = field(default_factory=SurfaceGrid)
    failure_angle: str = "min_n_gamma"
    cut_angle: float | None = None
    cut_depth: float = 0.05
    heel_clearance: float | None = None
    end_blade_angle: float | None = None
    curl_out_intervals: int = 0
    descend_clearance: float | None = None
    objective: str = "fill_energy"
    payload: PayloadOptions | None = None
    dump_height: float | None = None
    kept_target: float | None = None
    kept_target_scale: float = 1.0
    force_model: str = DEFAULT_FORCE_MODEL

    @property
    def force_payload(self) -> PayloadOptions | None:
        """The payload of the force model (the payload models: ``payload`` or the model's default), None for
        ``"fee"``."""
        return self.kept_payload if self.force_model in PAYLOAD_MODELS else None

    @property
    def kept_payload(self) -> PayloadOptions:
        """The payload state the kept objective uses (``payload``, else the force model's default, else
        :data:`~wheelloader.estimator.DEFAULT_PAYLOAD`)."""
        if self.payload is not None:
            return self.payload
        return check_force_model(self.force_model, None) if self.force_model in PAYLOAD_MODELS else DEFAULT_PAYLOAD

    @property
    def kept_dump_height(self) -> float:
        """The dump height of the kept objective [m] (``dump_height`` or the fixed path's end height)."""
        from .kept import dump_height

        return dump_height() if self.dump_height is None else float(self.dump_height)

    @property
    def curl_out(self) -> int:
        """Intervals of the curl-out phase at the end of a plan (``curl_out_intervals`` where an
        ``end_blade_angle`` is set, else 0)."""
        return self.curl_out_intervals if self.end_blade_angle is not None else 0

    @property
    def model_options(self) -> ModelOptions:
        """The force-model options the planner plans and checks with (the failure-angle rule; the carried load
        handed over at exit under ``"fee-payload"``)."""
        base = ModelOptions(failure_angle=self.failure_angle) if self.failure_angle != "min_n_gamma" \
            else DEFAULT_OPTIONS
        return model_options_for(self.force_model, base)

    def __post_init__(self) -> None:
        err = PlanningError
        check_choice("PlannerOptions.objective", self.objective, OBJECTIVES, error=err)
        check_choice("PlannerOptions.force_model", self.force_model, FORCE_MODELS, error=err)
        check_choice("PlannerOptions.solver", self.solver, SOLVERS, error=err)
        check_choice("PlannerOptions.qp_solver", self.qp_solver, QP_SOLVERS, error=err)
        if not isinstance(self.compiled, bool):
            raise PlanningError(f"PlannerOptions.compiled must be True or False, got {self.compiled!r}")
        if self.payload is not None and not isinstance(self.payload, PayloadOptions):
            raise PlanningError(f"PlannerOptions.payload must be a PayloadOptions, got {type(self.payload).__name__}")
        if self.dump_height is not None:
            check_finite("PlannerOptions.dump_height", self.dump_height, error=err)
        if self.kept_target is not None:
            check_range("PlannerOptions.kept_target", self.kept_target, 0.0, 10.0, error=err)
        check_range("PlannerOptions.kept_target_scale", self.kept_target_scale, 0.0, 2.0, low_open=True, error=err)
        check_choice("PlannerOptions.failure_angle", self.failure_angle, ("min_n_gamma", "min_weight_force"),
                     error=err)
        if self.cut_angle is not None:
            check_range("PlannerOptions.cut_angle", self.cut_angle, 0.0, math.pi / 2, low_open=True, high_open=True,
                        error=err)
        check_range("PlannerOptions.cut_depth", self.cut_depth, 0.0, None, error=err)
        if self.heel_clearance is not None:
            check_finite("PlannerOptions.heel_clearance", self.heel_clearance, error=err)
        if self.descend_clearance is not None:
            check_range("PlannerOptions.descend_clearance", self.descend_clearance, 0.0, None, error=err)
        if self.end_blade_angle is not None:
            check_range("PlannerOptions.end_blade_angle", self.end_blade_angle, *self.blade_angle_limits, error=err)
        check_int("PlannerOptions.intervals", self.intervals, minimum=4, maximum=400, error=err)
        check_int("PlannerOptions.curl_out_intervals", self.curl_out_intervals, minimum=0,
                  maximum=self.intervals // 2 - 1, error=err)
        for name in ("energy_weight", "smoothing_weight", "rho_margin", "end_clearance", "lift_headroom",
                     "validity_band"):
            check_range(f"PlannerOptions.{name}", getattr(self, name), 0.0, None, error=err)
        check_range("PlannerOptions.fill_limit", self.fill_limit, 0.0, 1.0, low_open=True, error=err)
        check_range("PlannerOptions.force_margin", self.force_margin, 0.0, 1.0, low_open=True, error=err)
        check_range("PlannerOptions.max_tilt_acceleration", self.max_tilt_acceleration, 0.0, None, low_open=True,
                    error=err)
        lo, hi = self.blade_angle_limits
        if not (-math.pi / 2 < lo < hi < math.pi / 2):
            raise PlanningError(f"PlannerOptions.blade_angle_limits must be (low, high) in (-pi/2, pi/2) rad, "
                                f"got {self.blade_angle_limits!r}")
        check_int("PlannerOptions.max_iter", self.max_iter, error=err)
        check_range("PlannerOptions.tolerance", self.tolerance, 0.0, None, low_open=True, error=err)
        if self.max_wall_time is not None:
            check_range("PlannerOptions.max_wall_time", self.max_wall_time, 0.0, None, low_open=True, error=err)


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
            object.__setattr__(self, name, check_finite(f"StartState.{name}", getattr(self, name), error=PlanningError))
        check_range("StartState.fill", self.fill, 0.0, None, error=PlanningError)

    @classmethod
    def from_observation(cls, obs: np.ndarray, capacity: float, payload: PayloadOptions | None = None) -> StartState:
        """From a ``BucketLoadingEnv`` observation (indices 0-5 pose and rates, 9 fill fraction).

        ``payload``: the env's under ``force_model="fee-payload"``, whose fill is the kept soil; the start's
        ``fill`` (the planner's carved volume) is then the volume that keeps it
        (:func:`~wheelloader.estimator.payload.removed_volume`, at the observed blade angle: a plan starts in
        or at the soil), at most the capacity.
        """
        o = [float(v) for v in np.asarray(obs, dtype=float).ravel()[:10]]
        fill = max(o[9], 0.0) * capacity
        if payload is not None:
            fill = min(removed_volume(fill, capacity, payload, 0.0, o[2]), capacity)
        return cls(o[0], o[1], o[2], o[3], o[4], o[5], fill)
