"""The cycle a plan is made for: start pose, duration, and the optimizers built once per settings."""

from __future__ import annotations

import threading
from dataclasses import replace
from typing import Any

from wheelloader.envs.config import nominal_start_pose
from wheelloader.estimator import Bucket, Loader, Pile

from .trajectory import PlannerOptions, StartState, TrajectoryOptimizer, first_rise

#: Duration of the digging motion once the tip is at the face [s] (the paper's 4.67 s cycle).
DIG_DURATION = 4.67
#: Speed assumed for the approach through the air to a carved face [m/s].
APPROACH_SPEED = 0.6

_OPTIMIZERS: dict[tuple, TrajectoryOptimizer] = {}
_OPTIMIZERS_LOCK = threading.Lock()


def optimizer_for(bucket: Bucket | None = None, loader: Loader | None = None,
                  options: PlannerOptions | None = None) -> TrajectoryOptimizer:
    """A cached :class:`TrajectoryOptimizer` (the NLP is built once per settings)."""
    key = (bucket or Bucket(), loader or Loader(), options or PlannerOptions())
    found = _OPTIMIZERS.get(key)
    if found is None:
        with _OPTIMIZERS_LOCK:  # threads planning side by side (planner.lanes) share one optimizer per settings
            found = _OPTIMIZERS.get(key)
            if found is None:
                found = _OPTIMIZERS[key] = TrajectoryOptimizer(*key)
    return found


def cautious_options(options: PlannerOptions, level: int = 1) -> PlannerOptions:
    """Wider safety margins for a re-plan: per ``level``, angle margin x(1 + 0.6 level), fill limit and
    force margin x0.9^level."""
    return replace(options, rho_margin=(1.0 + 0.6 * level) * options.rho_margin,
                   fill_limit=0.9**level * options.fill_limit, force_margin=0.9**level * options.force_margin)


def default_start(pile: Pile, cfg: Any = None) -> StartState:
    """The env's nominal start pose on ``pile`` (:func:`~wheelloader.envs.config.nominal_start_pose`), or
    with an env config ``cfg`` its ``start_pose``."""
    x, z, th = cfg.start_pose if cfg is not None else nominal_start_pose(pile)
    return StartState(x, z, th)


def cycle_duration(pile: Pile, start: StartState) -> float:
    """:data:`DIG_DURATION` plus the time to cross the air between ``start`` and the (carved) face [s]."""
    x_face = first_rise(pile, start, 0.05, step=0.01)
    gap = 0.0 if x_face is None else x_face - start.x
    return DIG_DURATION + max(0.0, gap - 0.3) / APPROACH_SPEED
