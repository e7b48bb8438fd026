"""The NLP of the full-cycle trajectory optimisation (CasADi + IPOPT).

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
* Energy: the env's bookkeeping (:func:`~wheelloader.envs.bookkeeping.step_work`),
  ``max(0, F_T ds_t + F_N ds_n)`` plus ``max(0, W_load dz)`` per interval
  (with a smooth max).
* Force model (:attr:`PlannerOptions.force_model`): ``"fee"`` counts ``V`` as the fill; under ``"fee-payload"``
  the fill is the payload's kept soil ``kept_volume(V)`` (in the objective, the ``min_fill`` bound and the payload's
  lifting work) and its weight is carried as the tip leaves the soil (``casadi_forces(carried_weight=)``);
  ``"fee-learned"`` adds the learned correction's CasADi twin at every node, at the interval's velocity
  (:func:`~wheelloader.planner.casadi_model.casadi_learned`; the start node at the start velocity), and keeps
  the plan inside the correction's trusted depth and speed (:func:`~.casadi_model.learned_trust`: beyond its
  training range the clipped correction has a kink at which IPOPT stopped converging).
* Objective: ``- V_N / capacity + lambda * E / 1 kJ + mu * sum |du|^2``
  (fill against energy; ``mu`` a small smoothing weight), optionally with a
  lower bound on the final fill ("least energy for a fill target"); or the opt-in energy per m^3 of kept
  soil (:mod:`.kept`: ``(E + E_lift) / V_kept``, scaled to O(1)) with a lower bound on ``V_kept``.
* Constraints: dynamics; velocity and acceleration limits of the loader;
  blade-angle and workspace limits; ``F_T <= margin * max_push_force`` and
  ``F_N <= margin * max_lift_force``; the validity domain where the tip is in
  soil, ``rho_min + rho_margin <= rho <= pi - eps1 - eps2 - delta - phi -
  rho_margin`` and ``-min(phi - slope_margin, alpha_max) + rho_margin <= alpha <= alpha_max - rho_margin``
  (the model's slope domain, :func:`~wheelloader.estimator.validity.alpha_lower_limit`), relaxed by
  :data:`VALIDITY_RELAX` times the height above ``validity_band`` over the surface, so they bind in soil
  and just above it; with ``midpoints`` forces and validity at the interval midpoints too; the start pose
  and velocity; and the end out of the pile, ``z_N >= z_s(x_N) + end_clearance``, while past the face every
  earlier node stays at most ``stay_clearance`` above the surface (no hop out and back in) once the env's
  ``exit_min_fill`` is loaded (before, the env lets the tip leave the soil, e.g. to pass over a carved wall
  whose slope the model cannot describe).
* An iteration callback (:class:`IterationMonitor`) hands the iterates to a caller that may stop the solve.

The NLP is built once per bucket, loader and :func:`structural_options` (the options that shape its
expressions) and cached, in memory and on disk (:mod:`.nlp_cache`: once per machine); its IPOPT solver once
per process and solver settings, the second and later ones on the first one's derivatives. Each call only
passes new parameters, bounds and the initial guess.
"""

from __future__ import annotations

import atexit
import math
import threading
import weakref
from collections.abc import Callable
from dataclasses import replace

import casadi as ca

from wheelloader.envs.bookkeeping import step_work
from wheelloader.estimator import DEFAULT_OPTIONS, GRAVITY, Bucket, Loader
from wheelloader.estimator.payload import kept_volume
from wheelloader.estimator.validity import alpha_lower_limit

from . import codegen, lanes, nlp_cache
from .casadi_model import casadi_forces, casadi_learned, learned_trust, smooth_max, smooth_min, smooth_pos
from .interrupt import guarded
from .kept import KEPT_OBJECTIVE_SCALE, kept_terms, smooth_lift
from .nlp_rules import RULES, compiled_if_present, hold_margin_variants
from .nlp_solver import make_solver, solver_settings
from .options import PlannerOptions

__all__ = ["VALIDITY_RELAX", "build", "compiled_if_present", "handle", "hold_margin_variants", "origin",
           "problem_function", "release", "structural_options"]

#: The NLPs of this process by (bucket, loader, structural options): expressions, layout, derivatives, solvers.
_CACHE: dict[tuple, dict] = {}
#: One thread at a time builds or looks up an NLP and its solvers (:mod:`.lanes`: threads that plan side by side).
_LOCK = threading.RLock()
#: How fast the validity-domain limits on rho relax above the surface [rad/m]: the limits bind in soil
#: and fade out within centimetres above it (a product ``depth * (rho - limit) >= 0`` would be degenerate
#: out of soil and blow up IPOPT's multipliers).
VALIDITY_RELAX = 30.0


#: Width of the smooth switch that follows the blade angle as the tip leaves the soil [m of depth]: under a payload
#: with a ``curl_gain`` and a curl-out phase (``PlannerOptions.curl_out_intervals``) the heaped capacity sees the
#: blade angle at the last node in soil (:func:`~wheelloader.estimator.payload.exit_angle_profile`), not the end
#: node's: the end node is then well above the soil, curled to the end blade angle whatever angle the tip left the
#: soil at. (Without a curl-out the end node is the one just out of the soil.)
EXIT_ANGLE_WIDTH = 0.005
#: Width of the smooth switch of the opt-in ``descend_clearance`` (the tip moves down only near the surface) [m],
#: and the slack on the tip's vertical speed where it is off [m/s] (above any loader's speed).
DESCEND_WIDTH = 0.01
DESCEND_SLACK = 10.0


#: Smoothing of the removed volume before the payload's kept soil [m^3]: ``kept_volume``'s second derivative is
#: infinite at 0 for a sharpness below 2 (the start node's V is 0), so V enters through a smooth positive part
#: (5e-7 m^3 at V = 0).
KEPT_SMOOTHING = 1e-6


def _kept_of(bucket: Bucket, payload):
    """The fill the NLP counts for a carved volume ``V``: ``V`` itself, or under ``"fee-payload"`` the payload's
    kept soil of it (:func:`~wheelloader.estimator.payload.kept_volume`) at the blade angle ``th`` the heap sees
    (where the payload has a ``curl_gain``: the angle at the last node in soil, :data:`EXIT_ANGLE_WIDTH`)."""
    if payload is None:
        return lambda v, th=0.0: v
    return lambda v, th=0.0: kept_volume(smooth_pos(v, KEPT_SMOOTHING), bucket.capacity, payload, 0.0, th)


def _smooth_work(v):
    """Smooth ``max(v, 0)`` of a step's work [J] (1 J wide)."""
    return smooth_pos(v, 1.0)


#: PlannerOptions fields that do not shape the NLP's expressions: IPOPT's settings (the solver is made per
#: value), the bounds on the decision variables and the energy weight (a parameter). (The margins stay constants
#: of the expressions: as parameters, CasADi differentiates ``F_T / (margin * F_max)`` in another floating-point
#: order, and the plans would change in their last bits.)
_NOT_STRUCTURAL = ("max_iter", "max_wall_time", "ipopt_warm_start", "tolerance", "energy_weight", "fill_limit",
                   "blade_angle_limits", "lift_headroom", "kept_target", "kept_target_scale", "solver", "qp_solver",
                   "compiled")
#: The derivatives each nlpsol plugin needs, by their nlpsol option name and the name of the solver's own function.
_DERIVATIVES = {"ipopt": (("grad_f", "nlp_grad_f"), ("jac_g", "nlp_jac_g"), ("hess_lag", "nlp_hess_l")),
                "sqpmethod": (("jac_fg", "nlp_jac_fg"), ("hess_lag", "nlp_hess_l"))}
#: The structural options that only set the margins of the constraints (what
#: :func:`~wheelloader.planner.cycle.cautious_options` widens for a re-plan): with ``hold_margin_variants(False)`` one
#: NLP per family in memory.
_MARGINS = ("rho_margin", "force_margin")


def structural_options(options: PlannerOptions) -> PlannerOptions:
    """``options`` with every field that does not shape the NLP's expressions at its default: two settings
    with the same structural options share one NLP (its expressions and derivatives)."""
    found = _STRUCTURAL.get(options)
    if found is None:  # replace() validates a new PlannerOptions (~40 us); a solve looks its NLP up several times
        defaults = PlannerOptions()
        found = replace(options, **{name: getattr(defaults, name) for name in _NOT_STRUCTURAL})
        if len(_STRUCTURAL) >= 64:
            _STRUCTURAL.clear()
        _STRUCTURAL[options] = found
    return found


#: :func:`structural_options` of the options seen in this process.
_STRUCTURAL: dict[PlannerOptions, PlannerOptions] = {}


def _margin_family(options: PlannerOptions) -> PlannerOptions:
    """``options`` with the margins (:data:`_MARGINS`) at their defaults: NLPs of one family differ only in
    the constants of their margins."""
    defaults = PlannerOptions()
    return replace(options, **{name: getattr(defaults, name) for name in _MARGINS})


def origin(bucket: Bucket, loader: Loader, options: PlannerOptions) -> str | None:
    """How this process obtained the NLP of these settings (:func:`.nlp_cache.origin` of their structural
    options); ``None`` if it was not built here."""
    return nlp_cache.origin(bucket, loader, structural_options(options))


def build(bucket: Bucket, loader: Loader, options: PlannerOptions):
    """The solver, its functions (``forces``, ``outputs``, ``constraints``, ``monitor``) and the constraint
    layout.

    Memoised per process at two levels: the NLP (expressions, layout and the derivatives IPOPT needs) once per
    bucket, loader and :func:`structural_options` (and once per machine on disk: :mod:`.nlp_cache`), and the
    IPOPT solver once per NLP and solver settings (iteration limit, tolerance, warm start). A second solver of
    an NLP is made from the first one's derivative functions (no new differentiation), so its iterates are
    bit-identical to those of a solver that built its own.
    """
    with _LOCK:
        return _build(bucket, loader, options)


def _build(bucket: Bucket, loader: Loader, options: PlannerOptions):
    """:func:`build` under its lock."""
    structural = structural_options(options)
    entry = _CACHE.get((bucket, loader, structural))
    if entry is None:
        # with hold_margin_variants(False) a margin variant of this NLP (the loop's wider-margin re-plans) takes the
        # place of the one in memory (~150 MB each): released before the build, so two are never held at once
        if not RULES["hold_margin_variants"]:
            for key in [key for key in _CACHE if key[:2] == (bucket, loader) and _margin_family(key[2])
                        == _margin_family(structural)]:
                del _CACHE[key]
        # the disk cache holds the NLP's expressions (plain CasADi Functions); the IPOPT solver with its
        # iteration callback (a Python object, not serialisable) is made on top of them in each process
        # CasADi may swallow a Ctrl-C while it builds or loads (as inside IPOPT): guarded re-raises it
        problem, functions, layout = guarded(nlp_cache.load_or_build, bucket, loader, structural, _build_nlp)
        entry = _CACHE[(bucket, loader, structural)] = _Entry(problem=problem, functions=functions, layout=layout,
                                                              derivatives={}, solvers={})
    settings = solver_settings(options)
    lane = lanes.current()
    if (settings, lane) not in entry["solvers"]:
        plugin = dict(settings)["plugin"]
        if lane != 0 and (settings, 0) not in entry["solvers"]:
            with lanes.lane(0):  # lane 0's solver differentiates; the other lanes' solvers reuse its derivatives
                _build(bucket, loader, options)
        derivatives = entry["derivatives"].get(plugin)
        from_library = False
        if lane != 0:
            use_library = options.compiled or RULES["compiled_if_present"]
            from_library = bool(use_library and entry.get(f"compiled {plugin}"))
            derivatives = entry[f"compiled {plugin}"] if from_library else derivatives
        elif options.compiled and options.solver == "sqp":  # the derivatives as compiled C (once per machine)
            if derivatives is None:  # the virtual machine's solver first: its derivative functions
                _build(bucket, loader, replace(options, compiled=False))
                derivatives = entry["derivatives"][plugin]
            if f"compiled {plugin}" not in entry:  # None: no compiler or a failed compile (logged)
                entry[f"compiled {plugin}"] = guarded(codegen.compiled, derivatives, f"planner_{plugin}")
            derivatives = entry[f"compiled {plugin}"] or derivatives
        elif options.compiled:  # IPOPT's derivatives as compiled C, found by the NLP's key (once per machine)
            if f"compiled {plugin}" not in entry:
                entry[f"compiled {plugin}"] = guarded(
                    codegen.compiled_by_key, nlp_cache.cache_key(bucket, loader, structural),
                    dict(_DERIVATIVES[plugin]), lambda: _virtual_derivatives(bucket, loader, options, plugin),
                    f"planner_{plugin}")
            derivatives = entry[f"compiled {plugin}"] or _virtual_derivatives(bucket, loader, options, plugin)
        elif plugin == "ipopt" and RULES["compiled_if_present"] and derivatives is None:
            # the library a compiled run made for this NLP, if this machine has one (nothing is compiled here)
            found = entry.get(f"compiled {plugin}") or guarded(
                codegen.present_by_key, nlp_cache.cache_key(bucket, loader, structural), dict(_DERIVATIVES[plugin]),
                f"planner_{plugin}")
            if found:
                entry[f"compiled {plugin}"] = derivatives = found
                from_library = True
        solver, monitor = guarded(make_solver, entry["problem"], settings, derivatives)
        if plugin not in entry["derivatives"] and not options.compiled and not from_library:
            entry["derivatives"][plugin] = {name: solver.get_function(own) for name, own in _DERIVATIVES[plugin]
                                            if solver.has_function(own)}
        entry["solvers"][(settings, lane)] = (solver, {**entry["functions"], "monitor": monitor})
    solver, functions = entry["solvers"][(settings, lane)]
    return solver, functions, entry["layout"]


def _virtual_derivatives(bucket: Bucket, loader: Loader, options: PlannerOptions, plugin: str) -> dict:
    """The derivative functions of ``plugin`` in CasADi's virtual machine (differentiated once per NLP)."""
    entry = _CACHE[(bucket, loader, structural_options(options))]
    if plugin not in entry["derivatives"]:
        build(bucket, loader, replace(options, compiled=False))
    return entry["derivatives"][plugin]


def problem_function(bucket: Bucket, loader: Loader, options: PlannerOptions) -> ca.Function:
    """The NLP of these settings as a CasADi Function ``(x, p) -> (f, g)`` (memoised as :func:`build`'s)."""
    build(bucket, loader, options)
    return _CACHE[(bucket, loader, structural_options(options))]["problem"]


class _Entry(dict):
    """One NLP of :data:`_CACHE` (a dict; a weak reference to it finds it again without keeping it in memory)."""


def handle(bucket: Bucket, loader: Loader, options: PlannerOptions) -> Callable[[], tuple]:
    """A function returning :func:`build`'s ``(solver, functions, layout)`` of these settings without holding
    them: it keeps a weak reference to the NLP's cache entry (a few dictionary look-ups per call) and builds
    it again when the entry was released (:func:`release`) or replaced by a margin variant (:func:`build`)."""
    settings = solver_settings(options)
    key = (bucket, loader, structural_options(options))
    ref: list = [lambda: None]

    def get() -> tuple:
        entry = ref[0]()
        solver_key = (settings, lanes.current())
        if entry is None or solver_key not in entry["solvers"]:
            with _LOCK:
                result = build(bucket, loader, options)
                ref[0] = weakref.ref(_CACHE[key])
            return result
        solver, functions = entry["solvers"][solver_key]
        return solver, functions, entry["layout"]

    return get


def release() -> int:
    """Drop this process's NLPs and solvers from memory (~150 MB each for the loop's 40 intervals); the next
    :func:`build` of one makes it again (from the disk cache's expressions). Returns how many were dropped."""
    with _LOCK:
        dropped = len(_CACHE)
        _CACHE.clear()
    return dropped


# The NLPs go while the interpreter is whole: a solver (its IPOPT callback is a Python object) destroyed when the
# module's globals are torn down at the interpreter's finalisation can abort the process (seen after Ctrl-C of
# `wheelloader plan --pareto`: "PyThreadState_Get ... finalizing", rc -6 instead of 130).
atexit.register(release)


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
    p_free = ca.SX.sym("free", 2)  # [on (0/1), fill below which the tip may leave the soil [m^3]]
    p = ca.vertcat(p_start, p_vel0, p_h, p_lam, p_soil, ca.vec(p_surf), ca.vec(p_ref), p_wref, p_face, p_free)
    # single-node force function (also used by predict)
    xs, zs, ths, vs = ca.SX.sym("x"), ca.SX.sym("z"), ca.SX.sym("th"), ca.SX.sym("V")
    p_win = ca.SX.sym("window", grid.window_size)
    alpha = grid.window_slope_angle(xs, p_win)
    vertical = grid.window_height(xs, p_win) - zs
    w_load = p_soil[0] * GRAVITY * vs
    payload = options.force_payload
    kept_of = _kept_of(bucket, payload)  # the fill the plan counts: V, or the payload's kept soil of it
    carried = None if payload is None else p_soil[0] * GRAVITY * kept_of(vs, ths)
    out = casadi_forces(p_soil, vertical, alpha - ths, alpha, w_load, bucket, options.model_options, carried)
    rho = alpha - ths
    f_node, n_node = out["F_T"], out["F_N"]
    velocity = []  # "fee-learned": the node's tip velocity, an input of its correction (the interval's)
    if options.force_model == "fee-learned":
        velocity = [ca.SX.sym("vx"), ca.SX.sym("vz")]
        c_t, c_n = casadi_learned(p_soil, out["depth"], rho, alpha, ths, vs, kept_of(vs, ths), *velocity, bucket)
        f_node, n_node = f_node + c_t, n_node + c_n
    forces = ca.Function("forces", [xs, zs, ths, vs, p_soil, p_win, *velocity], [f_node, n_node])
    node_fn = ca.Function("node", [xs, zs, ths, vs, p_soil, p_win, *velocity], [f_node, n_node, rho, vertical, alpha])

    def node(x_, z_, th_, v_, soil_, win_, vel_):
        return node_fn(x_, z_, th_, v_, soil_, win_, *([vel_[0], vel_[1]] if velocity else []))
    # decision variables
    X = ca.SX.sym("X", 4, n + 1)
    U = ca.SX.sym("U", 3, n)
    w = ca.vertcat(ca.vec(X), ca.vec(U))
    h = p_h
    g_eq, g_ineq = [], []
    energy = 0.0
    smooth = 0.0
    ft_all, fn_all = [], []
    ft0, fn0, _, vertical_prev, _ = node(X[0, 0], X[1, 0], X[2, 0], X[3, 0], p_soil, p_surf[:, 0], p_vel0)
    ft_all.append(ft0)
    fn_all.append(fn0)
    phi, delta = p_soil[3], p_soil[4]
    rho_lo = DEFAULT_OPTIONS.rho_min + options.rho_margin
    rho_hi = math.pi - DEFAULT_OPTIONS.eps1 - DEFAULT_OPTIONS.eps2 - delta - phi - options.rho_margin
    alpha_hi = DEFAULT_OPTIONS.alpha_max - options.rho_margin
    # the down-slope limit follows phi (validity.alpha_lower_limit): -min(phi - slope_margin, alpha_max)
    alpha_lo = alpha_lower_limit(phi, DEFAULT_OPTIONS, minimum=lambda a, b: smooth_min(a, b, 1e-3)) + options.rho_margin
    f_push = options.force_margin * loader.max_push_force
    f_lift = options.force_margin * loader.max_lift_force
    acc = loader.max_acceleration
    tilt_acc = options.max_tilt_acceleration
    prev_u = p_vel0
    # the blade angle the payload's heap sees (exit_angle_profile): the node's while in soil, held after the exit;
    # followed over the curl-out phase only (before it the tip stays in or just above the soil, and a switch over
    # every node would couple all the nodes' angles and depths in the Hessian: 3x the CPU per plan)
    track_exit = options.kept_payload.curl_gain != 0.0 and options.curl_out > 0
    exit_from = n - 1 - options.curl_out
    exit_angle = X[2, 0]
    trust_depth, trust_speed = learned_trust(bucket) if velocity else (0.0, 0.0)
    for k in range(n):
        xk, zk, tk, vk = X[0, k], X[1, k], X[2, k], X[3, k]
        xn, zn, tn, vn = X[0, k + 1], X[1, k + 1], X[2, k + 1], X[3, k + 1]
        u = U[:, k]
        dx, dz = h * u[0], h * u[1]
        # kinematics (exact for piecewise-constant velocity)
        g_eq += [xn - xk - dx, zn - zk - dz, tn - tk - h * u[2]]
        # forces at the new node (and its depth below the surface)
        f_t, f_n, rho_n, vertical, alpha_n = node(xn, zn, tn, vn, p_soil, p_surf[:, k + 1], u)
        vertical_start = vertical_prev  # depth at node k (vertical_prev moves on below)
        # fill: area between the start surface and the segment (trapezoid rule on the node depths),
        # capped by the bounds on V
        if options.midpoints:
            # the path between two nodes is a straight segment that can pass under a bump or graze a wall:
            # forces and validity are constrained at its midpoint too, and the fill is Simpson's rule
            xm, zm, tm, vm = 0.5 * (xk + xn), 0.5 * (zk + zn), 0.5 * (tk + tn), 0.5 * (vk + vn)
            f_tm, f_nm, rho_m, vertical_m, alpha_m = node(xm, zm, tm, vm, p_soil, p_surf[:, k + 1], u)
            slack_m = VALIDITY_RELAX * smooth_pos(-vertical_m - options.validity_band, 1e-3)
            g_ineq += [1.0 - f_tm / f_push, 1.0 - f_nm / f_lift, rho_m - rho_lo + slack_m, rho_hi - rho_m + slack_m,
                       alpha_hi - alpha_m + slack_m, alpha_m - alpha_lo + slack_m]
            removed = bucket.width * dx * (smooth_pos(vertical_prev, 1e-3) + 4.0 * smooth_pos(vertical_m, 1e-3)
                                           + smooth_pos(vertical, 1e-3)) / 6.0
        else:
            removed = bucket.width * dx * smooth_pos(0.5 * (vertical_prev + vertical), 1e-3)
        vertical_prev = vertical
        if track_exit and k + 1 > exit_from:
            in_soil = 0.5 * (1.0 + ca.tanh(vertical / EXIT_ANGLE_WIDTH))
            exit_angle = in_soil * tn + (1.0 - in_soil) * exit_angle
        else:
            exit_angle = tn
        g_eq.append(vn - vk - removed)
        if options.descend_clearance is not None:
            # opt-in: the tip moves down only while it starts the interval near the surface (or in soil); the
            # force model has no force for the bucket coming down onto the pile on its floor
            near = 0.5 * (1.0 + ca.tanh((vertical_start + options.descend_clearance) / DESCEND_WIDTH))
            g_ineq.append(u[1] + DESCEND_SLACK * near)
        # acceleration limits
        du = u - prev_u
        g_ineq += [acc * h - du[0], acc * h + du[0], acc * h - du[1], acc * h + du[1],
                   tilt_acc * h - du[2], tilt_acc * h + du[2]]
        smooth = smooth + ca.sumsqr(du / ca.vertcat(acc, acc, tilt_acc))
        prev_u = u
        # force limits and validity domain at the new node
        ft_all.append(f_t)
        fn_all.append(f_n)
        slack = VALIDITY_RELAX * smooth_pos(-vertical - options.validity_band, 1e-3)
        if k < n - 1 - options.curl_out:
            # once past the face the tip stays in or just above the soil until the last interval: the env
            # ends a cycle as soon as the tip has been in soil and is more than its exit clearance above
            # the surface; before the face (the approach over the ground) the constraint is off, and so it
            # is while less than the env's exit_min_fill is loaded (the env lets the tip leave the soil then)
            before_face = 0.5 * (1.0 + ca.tanh((p_face - xn) / 0.02))
            unloaded = p_free[0] * 0.5 * (1.0 - ca.tanh((vn - 0.5 * p_free[1]) / (0.1 * p_free[1] + 1e-9)))
            g_ineq.append(options.stay_clearance + vertical + 10.0 * (before_face + unloaded))
        g_ineq += [1.0 - f_t / f_push, 1.0 - f_n / f_lift, rho_n - rho_lo + slack, rho_hi - rho_n + slack,
                   alpha_hi - alpha_n + slack, alpha_n - alpha_lo + slack]
        if velocity:  # "fee-learned": inside the correction's trusted depth and speed (its training range)
            g_ineq += [trust_depth - vertical * ca.cos(alpha_n), trust_speed ** 2 - (u[0] * u[0] + u[1] * u[1])]
        if options.heel_clearance is not None:
            # opt-in: the bucket's heel (floor_length behind the tip along the blade) above the surface
            heel_x, heel_z = xn - bucket.floor_length * ca.cos(tn), zn - bucket.floor_length * ca.sin(tn)
            g_ineq.append(heel_z - grid.window_height(heel_x, p_surf[:, k + 1]) - options.heel_clearance)
        if options.cut_angle is not None:
            # opt-in cutting cone: deeper than cut_depth the velocity stays within cut_angle of the blade
            # (along >= cos(cut_angle - rho_margin) |v|, the margin as the validity domain's; off, by a
            # 10 m/s slack, above cut_depth and out of soil)
            # at both ends of the interval (the blade turns while the velocity is constant)
            speed = ca.sqrt(u[0] * u[0] + u[1] * u[1] + 1e-6)
            # it binds from 2 cm above cut_depth: the NLP's surface is smoothed, the check's is the polyline
            # the deeper end of the interval decides (a lift out of the soil ends shallow but starts deep)
            deeper = smooth_max(vertical_start, vertical, 1e-3)
            shallow = 0.5 * (1.0 - ca.tanh((deeper - options.cut_depth + 0.02) / 0.005))
            cone = max(options.cut_angle - options.rho_margin, 0.5 * options.cut_angle)
            for blade in (tk, tn):
                along = u[0] * ca.cos(blade) + u[1] * ca.sin(blade)
                g_ineq.append(along - math.cos(cone) * speed + 10.0 * shallow)
        # energy: the env's bookkeeping, with a smooth positive part (1 J wide)
        e_soil, e_payload = step_work(f_t, f_n, dx, dz, tn, p_soil[0] * GRAVITY * kept_of(vn, exit_angle), cos=ca.cos,
                                      sin=ca.sin, pos=_smooth_work)
        energy = energy + e_soil + e_payload
    # end out of the pile
    end_clear = X[1, n] - grid.window_height(X[0, n], p_surf[:, n]) - options.end_clearance
    g_ineq.append(end_clear)
    if options.end_blade_angle is not None:  # opt-in: end curled, carrying the load
        g_ineq.append(X[2, n] - options.end_blade_angle)
    exit_end = exit_angle if track_exit else X[2, n]
    fill_end = kept_of(X[3, n], exit_end)
    extra: dict[str, ca.Function] = {}
    if options.objective == "kept_per_energy":
        # opt-in (planner.kept): energy per m^3 of kept soil, the load lifted on to the dump height; the kept
        # fill (the payload state of the carved volume) is constrained from below by the solve's bounds
        kept, lift, total, per_kept = kept_terms(X[3, n], energy, X[1, n], p_soil[0], bucket.capacity,
                                                 options.kept_payload, options.kept_dump_height,
                                                 pos=lambda v: smooth_lift(v, sqrt=ca.sqrt), exit_angle=exit_end)
        main = per_kept * bucket.capacity / KEPT_OBJECTIVE_SCALE
        g_kept = [kept]
        extra["kept"] = ca.Function("kept", [w, p], [kept, lift, total, per_kept])
    else:
        main = -fill_end / bucket.capacity + p_lam * energy / 1000.0
        g_kept = []
    g = ca.vertcat(*g_eq, *g_ineq, fill_end, *g_kept)
    n_eq, n_ineq = len(g_eq), len(g_ineq)
    tracking = ca.sumsqr(X[0:2, 1:] - p_ref[:, 1:]) / n
    objective = main + options.smoothing_weight * smooth / n + p_wref * tracking
    problem = ca.Function("nlp", [w, p], [objective, g], ["x", "p"], ["f", "g"])
    outputs = ca.Function("outputs", [w, p], [ca.vertcat(*ft_all), ca.vertcat(*fn_all), energy])
    layout = {"ng": n_eq + n_ineq + 1 + len(g_kept), "ineq": slice(n_eq, n_eq + n_ineq), "fill_end": n_eq + n_ineq}
    if g_kept:
        layout["kept_end"] = n_eq + n_ineq + 1
    constraints = ca.Function("constraints", [w, p], [g])
    return problem, {"forces": forces, "outputs": outputs, "constraints": constraints, **extra}, layout
