"""Fill against energy over the energy weight: a Pareto sweep of the full-cycle planner.

:func:`pareto_sweep` solves the trajectory optimisation for a sequence of
energy weights lambda (cost per kJ, in bucket-fills), each warm-started from
the last accepted plan of the sweep, and re-simulates every plan with the
NumPy model (:func:`~wheelloader.planner.verify.verify_plan`). Fill and
energy of a point are those of the NumPy re-simulation, not the CasADi
prediction (which is kept as ``predicted_energy`` for comparison). A point
whose solve or check fails is kept and marked, never dropped: ``status`` and
``solver_ok`` say what IPOPT reported, ``check_ok`` and ``failures`` what the
re-simulation found. As in :func:`~wheelloader.planner.plan_next_cycle`,
a plan that passes the check is usable (``ok``) even when IPOPT stopped
without success; it is then feasible but not proven optimal for its lambda.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from wheelloader.estimator import Bucket, Loader, Pile, SoilParams, as_soil
from wheelloader.estimator.checks import check_range
from wheelloader.estimator.errors import PlanningError

from .cycle import cycle_duration, default_start, optimizer_for
from .mpc import ACCEPTED_STATUSES
from .trajectory import Plan, PlannerOptions, StartState
from .verify import PlanCheck, verify_plan

#: Default energy weights of a sweep [1/kJ].
DEFAULT_WEIGHTS: tuple[float, ...] = (0.0, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)


@dataclass(frozen=True, eq=False)
class ParetoPoint:
    """One plan of a :func:`pareto_sweep` (SI units).

    Attributes
    ----------
    energy_weight : float
        lambda [1/kJ].
    fill : float
        Fill of the NumPy re-simulation [m^3].
    fill_fraction : float
        ``fill`` over the bucket capacity.
    energy : float
        Energy of the NumPy re-simulation [J].
    energy_per_m3 : float
        ``energy / fill`` [J/m^3] (``inf`` when nothing was filled).
    predicted_energy : float
        Energy the CasADi model predicted [J].
    status : str
        IPOPT's return status.
    solver_ok : bool
        Whether the status is an accepted one (success or acceptable level).
    check_ok : bool
        Whether the NumPy re-simulation passed every constraint check.
    failures : tuple of str
        The failed checks (empty when ``check_ok``).
    solve_time : float
        Wall time of the IPOPT call [s].
    iterations : int
        IPOPT iterations.
    warm_started : bool
        Whether the solve started from a previous plan of the sweep.
    pareto_optimal : bool
        Whether the point is ``ok`` and no other ``ok`` point has at least its
        fill for at most its energy (and is better in one of them): the pairs
        are those of the NumPy re-simulation, so a feasible plan counts even
        when IPOPT did not prove it optimal.
    plan, check : Plan, PlanCheck
        The plan and its check (not serialised by :meth:`to_dict`).
    """

    energy_weight: float
    fill: float
    fill_fraction: float
    energy: float
    energy_per_m3: float
    predicted_energy: float
    status: str
    solver_ok: bool
    check_ok: bool
    failures: tuple[str, ...]
    solve_time: float
    iterations: int
    warm_started: bool
    pareto_optimal: bool = False
    plan: Plan | None = field(default=None, repr=False)
    check: PlanCheck | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        """Whether the plan is usable: the NumPy re-simulation passed every check.

        With ``solver_ok`` false the plan is feasible but not proven optimal.
        """
        return self.check_ok

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping (non-finite numbers as ``None``)."""
        out: dict[str, Any] = {}
        for name in ("energy_weight", "fill", "fill_fraction", "energy", "energy_per_m3", "predicted_energy",
                     "status", "solver_ok", "check_ok", "solve_time", "iterations", "warm_started", "pareto_optimal"):
            value = getattr(self, name)
            if isinstance(value, float) and not math.isfinite(value):
                value = None
            out[name] = value
        out["ok"] = self.ok
        out["failures"] = list(self.failures)
        return out


def pareto_sweep(soil: SoilParams | str | dict, pile: Pile, weights: Sequence[float] = DEFAULT_WEIGHTS,
                 start: StartState | None = None, bucket: Bucket | None = None, loader: Loader | None = None,
                 options: PlannerOptions | None = None, *, duration: float | None = None,
                 rate: float = 60.0) -> list[ParetoPoint]:
    """Plan for each energy weight and re-simulate each plan with the NumPy model.

    The first weight is solved from the planner's default initial guess; each
    later one starts from the last plan of the sweep that passed the check
    (or the default guess if there is none yet).

    Parameters
    ----------
    soil : SoilParams, preset name or dict
        Soil to plan with.
    pile : Pile
        Surface at the start of the cycle.
    weights : sequence of float
        Energy weights lambda [1/kJ], solved in the given order (default
        :data:`DEFAULT_WEIGHTS`); each finite and >= 0.
    start : StartState, optional
        Start of the plan (default :func:`~wheelloader.planner.default_start`).
    bucket, loader, options : optional
        Machine and planner settings (the optimiser is cached per settings).
    duration : float, optional
        Cycle duration [s] (default :func:`~wheelloader.planner.cycle_duration`).
    rate : float
        Sampling rate of the NumPy re-simulation [Hz].

    Returns
    -------
    list of ParetoPoint
        One point per weight, in the order of ``weights`` (failed ones included).
    """
    soil = as_soil(soil)
    if not isinstance(pile, Pile):
        raise PlanningError(f"pile must be a Pile, got {type(pile).__name__}")
    try:
        lams = [float(w) for w in weights]
    except (TypeError, ValueError):
        raise PlanningError(f"weights must be a sequence of numbers, got {weights!r}") from None
    if not lams:
        raise PlanningError("weights must not be empty")
    for lam in lams:
        check_range("energy weights [per kJ]", lam, 0.0, None, error=PlanningError)
    opt = optimizer_for(bucket, loader, options)
    start = start or default_start(pile)
    duration = cycle_duration(pile, start) if duration is None else duration
    capacity = opt.bucket.capacity
    points: list[ParetoPoint] = []
    guess: Plan | None = None
    for lam in lams:
        plan = opt.solve(soil, pile, start, duration, energy_weight=lam, initial_guess=guess)
        check = verify_plan(plan, soil, pile, opt.bucket, opt.loader, opt.options, rate=rate)
        solver_ok = plan.status in ACCEPTED_STATUSES
        fill, energy = float(check.fill), float(check.energy)
        points.append(ParetoPoint(
            energy_weight=lam, fill=fill, fill_fraction=fill / capacity, energy=energy,
            energy_per_m3=energy / fill if fill > 0.0 else math.inf, predicted_energy=float(plan.energy),
            status=plan.status, solver_ok=solver_ok, check_ok=check.ok, failures=tuple(check.failures),
            solve_time=float(plan.solve_time), iterations=plan.iterations, warm_started=guess is not None,
            plan=plan, check=check))
        if check.ok:
            guess = plan
    return mark_pareto_optimal(points)


def mark_pareto_optimal(points: Sequence[ParetoPoint]) -> list[ParetoPoint]:
    """The points with ``pareto_optimal`` set: ``ok`` and not dominated by another ``ok`` point.

    ``a`` dominates ``b`` when ``a.fill >= b.fill`` and ``a.energy <= b.energy``
    with one of them strict.
    """
    good = [p for p in points if p.ok]

    def dominated(p: ParetoPoint) -> bool:
        return any(q.fill >= p.fill and q.energy <= p.energy and (q.fill > p.fill or q.energy < p.energy)
                   for q in good if q is not p)

    return [replace(p, pareto_optimal=p.ok and not dominated(p)) for p in points]
