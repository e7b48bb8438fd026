"""The planner's CasADi solver for an NLP: its plugin settings (IPOPT or CasADi's SQP) and the solver itself.

:func:`solver_settings` gives the nlpsol plugin and its options for a :class:`PlannerOptions` as a hashable key
(the key of a solver within its NLP, :mod:`.nlp`); :func:`make_solver` builds the solver on an NLP's problem
function with an :class:`IterationMonitor`, reusing derivative functions handed to it.
"""

from __future__ import annotations

import casadi as ca

from .iteration_monitor import IterationMonitor
from .options import PlannerOptions


def solver_settings(options: PlannerOptions) -> tuple[tuple[str, object], ...]:
    """The nlpsol plugin and its options for ``options`` (hashable: the key of a solver within its NLP)."""
    if options.solver == "sqp":
        # CasADi's SQP: exact Hessian of the Lagrangian, regularised to be convex for the QP solver
        return (("plugin", "sqpmethod"), ("qpsol", options.qp_solver), ("max_iter", options.max_iter),
                ("tol_pr", options.tolerance), ("tol_du", options.tolerance), ("convexify_strategy", "regularize"),
                ("compiled", options.compiled))
    settings: dict[str, object] = {
        "plugin": "ipopt", "ipopt.max_iter": options.max_iter, "ipopt.tol": options.tolerance,
        "ipopt.acceptable_tol": 1e-3, "ipopt.acceptable_iter": 5, "ipopt.mu_strategy": "adaptive",
    }
    if options.max_wall_time is not None:
        settings["ipopt.max_wall_time"] = float(options.max_wall_time)
    if options.ipopt_warm_start:
        settings.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-4,
                         "ipopt.warm_start_bound_push": 1e-6, "ipopt.warm_start_mult_bound_push": 1e-6})
    if options.compiled:
        settings["compiled"] = True
    return tuple(settings.items())


#: Options that keep each QP solver of ``sqpmethod`` quiet and failures non-fatal (the SQP reports them).
_QP_OPTIONS: dict[str, dict[str, object]] = {
    "daqp": {}, "qpoases": {"printLevel": "none"},
    "osqp": {"verbose": False, "osqp": {"verbose": False, "eps_abs": 1e-8, "eps_rel": 1e-8, "polish": True}},
}


def make_solver(problem, settings: tuple[tuple[str, object], ...], derivatives: dict | None):
    """The solver on ``problem`` (a Function ``(x, p) -> (f, g)``) with an :class:`IterationMonitor`; with
    ``derivatives`` (another solver's derivative functions of the same problem and plugin: IPOPT's ``grad_f``,
    ``jac_g`` and ``hess_lag``, sqpmethod's ``jac_fg`` and ``hess_lag``) nothing is differentiated again."""
    opts = dict(settings)
    plugin = opts.pop("plugin")
    opts.pop("compiled", None)  # build() passes the compiled derivatives
    solver_opts = {"print_time": False, "error_on_fail": False,
                   # the multipliers of the parameters are never read: no Jacobian with respect to p
                   "calc_lam_p": False, **opts, **(derivatives or {})}
    if plugin == "ipopt":
        # no gradient of the Lagrangian either (nlp_grad: computed only for lam_p, lam_x, f or g after the
        # solve, none of which is asked for; ~380k instructions, 23 MB and 0.35 s CPU per 40-interval NLP)
        solver_opts.update({"ipopt.print_level": 0, "ipopt.sb": "yes", "no_nlp_grad": True})
    else:
        solver_opts.update({"print_header": False, "print_iteration": False, "print_status": False,
                            "qpsol_options": {"error_on_fail": False, **_QP_OPTIONS[str(opts["qpsol"])]}})
    monitor = IterationMonitor(problem.size1_in(0), problem.size1_out(1))
    solver_opts["iteration_callback"] = monitor
    return ca.nlpsol("bucket_path", plugin, problem, solver_opts), monitor
