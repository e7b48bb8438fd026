"""Two-cycle look-ahead between cycles (#33 item 2): plan the next cycle with the one after it in view.

Each candidate plan of the next cycle (the greedy plan and variants of its settings, :data:`CANDIDATES`) is
followed by the greedy plan of the cycle after it, made on the pile the candidate leaves (the pile carved along
the candidate's path up to where the env would end its cycle). The loop's fallback stands in for a next plan
that fails its check, as in the loop. The candidate whose two cycles together cost the least energy per m^3
of kept soil, loads lifted on to the dump height (:mod:`.kept`, the NumPy model with the calibrated
parameters), is dug; a later candidate wins only when it is cheaper by more than
:data:`~wheelloader.estimator.quantise.TIE_RELATIVE` (on a near-tie the earlier stays, so the greedy plan
wins ties). Budgets are IPOPT iteration counts (each plan's, as :func:`plan_next_cycle`), so the choice is the
same on any machine. It uses only the planner's public functions (:func:`plan_next_cycle`,
:func:`model_bezier_on_face`, :func:`path_energy`).

Two cheaper settings (the loop's default, :data:`FAST`): ``second="bezier"`` scores the cycle after a
candidate with the Bezier path placed geometrically on the pile it leaves (:func:`bezier_on_face`, one NumPy
simulation, no IPOPT) instead of its greedy plan, and ``candidate_iterations`` starts every candidate after the
first from the first one's plan (IPOPT's start point) within that many iterations, without re-plans. The greedy
plan is then the loop's plan, and the look-ahead adds ``candidate_iterations`` per extra candidate.

Aoshima et al. (2025, Automation 6(3):31) plan over the next loadings the same way (a rollout of candidate
plans).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

from wheelloader.estimator import Bucket, BucketPath, Pile, SoilParams, as_soil
from wheelloader.estimator.quantise import better, quantise_pile, quantise_soil

from .fallback import LOOP_EXIT_MIN_FILL, _kept, bezier_on_face, model_bezier_on_face
from .kept import KeptTerms, evaluate
from .next_cycle import PlanOutcome, plan_next_cycle
from .options import PlannerOptions
from .verify import path_energy

__all__ = ["CANDIDATES", "FAST", "FAST_CANDIDATES", "KEPT_CANDIDATES", "SECOND_CYCLE", "LookaheadChoice",
           "plan_with_lookahead", "two_cycle_cost"]

#: The candidates of the next cycle: a name and the planner settings it changes (the first is the greedy plan).
CANDIDATES: tuple[tuple[str, Mapping[str, Any]], ...] = (
    ("greedy", {}),
    ("fill limit 0.80", {"fill_limit": 0.80}),
    ("energy weight 0.04/kJ", {"energy_weight": 0.04}),
)
#: The candidates under the kept objective (``PlannerOptions(objective="kept_per_energy")``): the greedy plan and
#: its least kept fill 5 % below and above the fixed path's. :data:`CANDIDATES` give the greedy plan there: the energy
#: weight does not enter that objective, and with a fill limit of 0.80 no plan passed in 9 of the 10
#: cycles of the MPM loop that were measured (``docs/results/lookahead_mpm.md``).
KEPT_CANDIDATES: tuple[tuple[str, Mapping[str, Any]], ...] = (
    ("greedy", {}),
    ("kept target -5 %", {"kept_target_scale": 0.95}),
    ("kept target +5 %", {"kept_target_scale": 1.05}),
)
#: How the cycle after a candidate is scored: its greedy plan on the pile the candidate leaves (the loop's
#: fallback where that plan fails), or the Bezier path placed geometrically there (no IPOPT).
SECOND_CYCLE = ("plan", "bezier")
#: The fast look-ahead's candidates: greedy and one with a lower fill limit.
FAST_CANDIDATES: tuple[tuple[str, Mapping[str, Any]], ...] = CANDIDATES[:2]
#: The fast look-ahead's settings (keywords of :func:`plan_with_lookahead`): each extra candidate warm-started
#: from the greedy plan within 20 IPOPT iterations, the next cycle scored with the geometric Bezier placement,
#: a candidate chosen over greedy only when it promises at least 5 % less energy per m^3 kept over two cycles.
FAST: Mapping[str, Any] = {"candidates": FAST_CANDIDATES, "second": "bezier", "candidate_iterations": 20,
                           "margin": 0.05}


@dataclass
class LookaheadChoice:
    """What the look-ahead weighed: per candidate its name, two-cycle cost [J/m^3 kept] (inf: not usable) and
    the terms of both cycles; the chosen index and the IPOPT iterations spent."""

    names: list[str]
    costs: list[float]
    cycles: list[tuple[KeptTerms | None, KeptTerms | None]]
    chosen: int
    iterations: int
    details: dict[str, Any] = field(default_factory=dict)


def _dug_part(path: BucketPath, pile: Pile, bucket: Bucket, exit_min_fill: float) -> tuple[BucketPath, Pile]:
    """The part of ``path`` the env digs (up to where it ends the cycle) and the pile it leaves."""
    _, end = _kept(pile, path.x, path.z, bucket, exit_min_fill)
    part = BucketPath(path.t[:end + 1], path.x[:end + 1], path.z[:end + 1], path.blade_angle[:end + 1], path.name)
    return part, pile.carve(part.x, part.z, bucket.width, bucket.capacity).pile


def _path_terms(path: BucketPath, soil: SoilParams, pile: Pile, bucket: Bucket, options: PlannerOptions
                ) -> KeptTerms:
    """Kept fill, energy with the lift and energy per kept m^3 of a dug path by the NumPy model."""
    sim = path_energy(path, soil, pile, bucket, model_options=options.model_options, payload=options.force_payload,
                      learned=options.force_model == "fee-learned")
    return evaluate(sim["carved"], sim["energy"], float(path.z[-1]), soil.gamma, bucket.capacity,
                    options.kept_payload, options.kept_dump_height, float(path.blade_angle[-1]))


def two_cycle_cost(first: KeptTerms | None, second: KeptTerms | None) -> float:
    """Energy per m^3 of kept soil over two cycles [J/m^3]: ``(E1 + E2) / (V1 + V2)`` (inf without a first)."""
    if first is None:
        return float("inf")
    energy = first.energy + (second.energy if second is not None else 0.0)
    kept = first.kept + (second.kept if second is not None else 0.0)
    return energy / kept if kept > 0.0 else float("inf")


def plan_with_lookahead(params: SoilParams | str | dict, pile: Pile, *, options: PlannerOptions | None = None,
                        candidates: Sequence[tuple[str, Mapping[str, Any]]] = CANDIDATES,
                        planner: Callable[..., PlanOutcome] = plan_next_cycle,
                        exit_min_fill: float = LOOP_EXIT_MIN_FILL, control_rate: float = 60.0,
                        second: str = "plan", candidate_iterations: int | None = None, margin: float = 0.0,
                        **planner_kwargs: Any) -> PlanOutcome:
    """The next cycle's plan chosen with the cycle after it in view (module docstring).

    Parameters
    ----------
    params, pile
        As :func:`plan_next_cycle` (calibrated soil; the pile at the start of the cycle).
    options : PlannerOptions, optional
        The greedy planner's settings; each candidate replaces some of them.
    candidates : sequence of (name, mapping)
        Names and setting changes (:data:`CANDIDATES`); the first should be the greedy plan (it wins ties).
    planner : callable
        ``planner(params, pile, options=, exit_min_fill=, control_rate=, **planner_kwargs) -> PlanOutcome``
        (default :func:`plan_next_cycle`).
    exit_min_fill, control_rate
        The env's end-of-cycle rule and the control rate (as the loop's).
    second : {"plan", "bezier"}
        How the cycle after each candidate is scored (:data:`SECOND_CYCLE`): its greedy plan (IPOPT) or the
        geometric Bezier placement on the pile the candidate leaves (one NumPy simulation).
    candidate_iterations : int, optional
        When given, every candidate after the first starts from the first one's plan (where it has one) and
        gets at most this many IPOPT iterations, without re-plans; None: each is planned as the first.
    margin : float
        A candidate after the first is chosen only when its two-cycle cost is below ``(1 - margin)`` times the
        first's (the model that predicts it misses the next cycle's force by ~20 %: a smaller predicted gain is
        noise); 0: the cheapest wins (ties to the earlier).
    **planner_kwargs
        Passed on to ``planner`` (e.g. ``mpc``, ``replan_within_iterations``).

    Returns
    -------
    PlanOutcome
        The chosen candidate's outcome; ``message`` names it and the two-cycle costs, and the outcome carries
        a :class:`LookaheadChoice` as ``lookahead`` (an attribute).
    """
    tic = time.perf_counter()
    if second not in SECOND_CYCLE:
        raise ValueError(f"second must be one of {SECOND_CYCLE}, got {second!r}")
    if candidate_iterations is not None and (not isinstance(candidate_iterations, int) or candidate_iterations < 1):
        raise ValueError(f"candidate_iterations must be a positive integer or None, got {candidate_iterations!r}")
    if not 0.0 <= margin < 1.0:
        raise ValueError(f"margin must be in [0, 1), got {margin!r}")
    # the force model the loop calibrated (plan_next_cycle's force_model=, payload=) judges the candidates too
    model = {k: planner_kwargs.pop(k) for k in ("force_model", "payload") if planner_kwargs.get(k) is not None}
    options = replace(options or PlannerOptions(), **model)
    soil, pile = quantise_soil(as_soil(params)), quantise_pile(pile)
    bucket = Bucket()
    names, costs, cycles, outcomes = [], [], [], []
    iterations = 0
    best, best_cost = None, float("inf")
    for k, (name, change) in enumerate(candidates):
        variant = replace(options, **dict(change))
        kwargs = dict(planner_kwargs)
        if k > 0 and candidate_iterations is not None:
            variant = replace(variant, max_iter=candidate_iterations)
            kwargs["replan_within_iterations"] = 0  # no re-plans: the budget is the candidate's iterations
            warm = outcomes[0].plan if outcomes and outcomes[0].success else None
            if warm is not None:
                kwargs["initial_guess"] = warm
        first = planner(soil, pile, options=variant, exit_min_fill=exit_min_fill, control_rate=control_rate,
                        **kwargs)
        iterations += _iterations(first)
        terms1 = terms2 = None
        if first.success and first.path is not None:
            dug, next_pile = _dug_part(first.path, pile, bucket, exit_min_fill)
            terms1 = _path_terms(dug, soil, pile, bucket, variant)
            if second == "bezier":
                path2 = bezier_on_face(next_pile, control_rate, bucket, exit_min_fill=exit_min_fill)
            else:
                after = planner(soil, next_pile, options=options, exit_min_fill=exit_min_fill,
                                control_rate=control_rate, **{**planner_kwargs, "mpc": False})
                iterations += _iterations(after)
                path2 = after.path if after.success and after.path is not None else model_bezier_on_face(
                    soil, next_pile, control_rate, bucket, exit_min_fill=exit_min_fill,
                    model_options=options.model_options, payload=options.force_payload,
                    learned=options.force_model == "fee-learned")
            dug2, _ = _dug_part(path2, next_pile, bucket, exit_min_fill)
            terms2 = _path_terms(dug2, soil, next_pile, bucket, options)
        cost = two_cycle_cost(terms1, terms2)
        names.append(name)
        costs.append(cost)
        cycles.append((terms1, terms2))
        outcomes.append(first)
        clears = k == 0 or not margin or cost < (1.0 - margin) * costs[0]
        if best is None or (clears and better(cost, best_cost)):
            best, best_cost = k, cost
    chosen = outcomes[best]
    chosen.lookahead = LookaheadChoice(names, costs, cycles, best, iterations)
    listed = ", ".join(f"{n} {c / 1e3:.1f}" for n, c in zip(names, costs, strict=True))
    chosen.message = (f"look-ahead chose {names[best]} ({listed} kJ/m^3 kept over two cycles; {iterations} IPOPT "
                      f"it.): {chosen.message}")
    chosen.seconds = time.perf_counter() - tic
    return chosen


def _iterations(outcome: PlanOutcome) -> int:
    """IPOPT iterations of an outcome's plan (0 without one)."""
    return int(outcome.plan.iterations) if outcome.plan is not None else 0
