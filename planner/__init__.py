"""CasADi trajectory optimisation and MPC for the next cycle's bucket path.

* :class:`TrajectoryOptimizer`: full-cycle plan (fill against energy) on the
  FEE force model written in CasADi (:mod:`.casadi_model`), IPOPT, built once.
* :class:`MPCController` / :func:`make_env_policy`: shrinking-horizon MPC in
  ``BucketLoadingEnv``, with a checked solver status and a safe fallback.
* :func:`plan_next_cycle`: the planner of the cycle-to-cycle loop.
* :func:`verify_plan`: re-simulation of a plan with the NumPy model.
* :func:`pareto_sweep`: fill against energy over the energy weight.
"""

from .loop import cycle_duration, default_start, optimizer_for, plan_next_cycle
from .mpc import MPCController, make_env_policy
from .pareto import DEFAULT_WEIGHTS, ParetoPoint, mark_pareto_optimal, pareto_sweep
from .trajectory import Plan, PlannerOptions, StartState, TrajectoryOptimizer
from .verify import PlanCheck, path_energy, verify_plan

__all__ = ["DEFAULT_WEIGHTS", "MPCController", "ParetoPoint", "Plan", "PlanCheck", "PlannerOptions", "StartState",
           "TrajectoryOptimizer", "cycle_duration", "default_start", "make_env_policy", "mark_pareto_optimal",
           "optimizer_for", "pareto_sweep", "path_energy", "plan_next_cycle", "verify_plan"]
