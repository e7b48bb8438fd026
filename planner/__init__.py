"""CasADi trajectory optimisation and MPC for the next cycle's bucket path.

* :class:`TrajectoryOptimizer`: full-cycle plan (fill against energy) on the
  FEE force model written in CasADi (:mod:`.casadi_model`), IPOPT, built once.
* :class:`MPCController` / :func:`make_env_policy`: shrinking-horizon MPC in
  ``BucketLoadingEnv``, with a checked solver status and a safe fallback.
* :func:`plan_next_cycle`: the planner of the cycle-to-cycle loop and of ``wheelloader plan``
  (:class:`PlanOutcome`); :func:`bezier_on_face` / :func:`model_bezier_on_face`: its fallback paths.
* :func:`verify_plan`: re-simulation of a plan with the NumPy model.
* :func:`pareto_sweep`: fill against energy over the energy weight.
"""

from .cycle import cautious_options, cycle_duration, default_start, optimizer_for
from .fallback import LOOP_EXIT_MIN_FILL, MODEL_FALLBACK_NAME, bezier_on_face, model_bezier_on_face
from .mpc import MPCController, make_env_policy
from .next_cycle import PlanOutcome, plan_next_cycle
from .pareto import DEFAULT_WEIGHTS, ParetoPoint, mark_pareto_optimal, pareto_sweep
from .trajectory import Plan, PlannerOptions, StartState, TrajectoryOptimizer
from .verify import PlanCheck, path_energy, verify_plan

__all__ = ["DEFAULT_WEIGHTS", "LOOP_EXIT_MIN_FILL", "MODEL_FALLBACK_NAME", "MPCController", "ParetoPoint", "Plan",
           "PlanCheck", "PlanOutcome", "PlannerOptions", "StartState", "TrajectoryOptimizer", "bezier_on_face",
           "cautious_options", "cycle_duration", "default_start", "make_env_policy", "mark_pareto_optimal",
           "model_bezier_on_face", "optimizer_for", "pareto_sweep", "path_energy", "plan_next_cycle", "verify_plan"]
