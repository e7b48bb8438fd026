"""The adaptation loop, one for every plant: plan, dig in the plant, measure, calibrate, plan again.

:func:`run_loop` closes the loop on anything with the reference-plant interface
(:class:`wheelloader.references.Plant`: ``dig(path, pile, soil, seed) -> CycleLog`` with the carved pile in
``pile_after``): the FEE env (:class:`~wheelloader.references.fee_env.FEEEnvPlant`; with ``keep_env=True`` one
env digs every cycle, its soil drifting between them, and controller strategies such as the MPC or a trained
policy act on its observations), the plane-strain MPM continuum (:class:`~wheelloader.references.mpm.MPMPlant`)
or the Yade DEM (:class:`~wheelloader.references.dem.DEMPlant`); :func:`wheelloader.references.make_plant`
builds one by name. The strategies are those of :mod:`wheelloader.adaptation`.

Every metric is measured by the plant, the same way for every strategy. A plant that measures a cycle itself
puts its figures in the log's ``metadata["measured"]`` (the FEE env with ``keep_env``: its fill, energy, stall
and validity-domain steps); otherwise the loop measures them from the log:

* energy: the work the bucket does on the soil along the path, ``-sum F . v dt`` with ``F`` the plant's
  bucket force (F_T, F_N turned back into the world frame) and ``v`` the tip velocity
  (:func:`wheelloader.references.metrics.cycle_work`); the carried load's weight is in ``F``, so lifting
  it is counted;
* fill: the plant's soil inside the bucket at the end of the path;
* validity-domain steps: in-soil samples where the model, with the parameters planned with, is outside its
  validity domain.

The next-cycle prediction error is the F_R RMSE of the parameters the strategy planned with against the
plant's force, filtered with the references' Gaussian (σ 0.1 s; none for the FEE env with ``keep_env``, whose
sensor noise the calibration sees raw, as a machine's logger would give it), over the in-soil samples. Between
cycles the strategies calibrate on that same log.

With ``cache``, each cycle's log is saved as it finishes (:mod:`wheelloader.saved_loops`), and a loop that finds
a saved cycle whose path equals the one it planned reads it instead of digging again: an interrupted run
resumes where it stopped.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.adaptation import Calibrating, CalibrationStep, CycleRecord, Strategy
from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    FLAG_OUT_OF_SOIL,
    CalibrationOptions,
    CycleLog,
    ModelOptions,
    Pile,
    SoilParams,
    WheelloaderError,
    calibrate,
    predict,
    preset,
)
from wheelloader.estimator.payload import as_payload
from wheelloader.planner import PlanOutcome
from wheelloader.references.filtering import DEFAULT_FILTER, filtered
from wheelloader.references.metrics import cycle_work
from wheelloader.references.plant import Plant
from wheelloader.saved_loops import (
    STALE_CHOICES,
    PlanRecord,
    SavedCycle,
    cycle_file,
    load_saved_cycle,
    path_digest,
    resolve_saved_cycle,
    save_cycle,
)

#: ``sigma_s`` of :func:`run_loop` that takes the plant's own filter (its ``filter_sigma_s`` attribute where it has
#: one, else the references' :data:`~wheelloader.references.filtering.DEFAULT_FILTER`).
PLANT_FILTER = "plant"


def run_loop(plant: Plant, strategy: Strategy, pile: Pile | Mapping[str, Any], soil: SoilParams | str,
             cycles: int = 5, *, seed: int = 0, cache: str | Path | None = None,
             sigma_s: float | str | None = PLANT_FILTER, progress: Callable[[str], None] | None = None,
             stale: str = "error") -> tuple[list[CycleRecord], list[CycleLog]]:
    """Run ``cycles`` cycles of ``strategy`` in ``plant``, each on the pile the previous one carved.

    Parameters
    ----------
    plant : Plant
        The plant that digs (its ``dig`` must return the carved surface in ``pile_after``). Optional parts of
        the interface it may have: ``start_cycle(pile, soil, seed=, first=) -> Pile`` (the pile the next cycle
        starts on, for a plant that carries its own state from cycle to cycle), ``accepts_controller`` (True:
        ``dig(..., controller=)`` executes a controller strategy's feedback controller), ``true_soil(soil)``
        (the truth the oracle learns), ``filter_sigma_s`` (its force filter, see ``sigma_s``).
    strategy : Strategy
        A strategy of :mod:`wheelloader.adaptation`: one that plans paths, or (on a plant that accepts
        controllers) one that gives a controller.
    pile : Pile or mapping
        Surface before the first cycle (a mapping of the env's ``pile`` keywords only for a plant with
        ``start_cycle``, which builds its own).
    soil : SoilParams or str
        The plant's soil (hidden from the strategy; the plant documents which fields it uses).
    cycles : int
        Cycles to dig (>= 1).
    seed : int
        Seed of the plant (packing, jitter, sensor noise).
    cache : str or Path, optional
        Folder where each cycle's log is saved as ``cycle<k>.csv.xz`` + ``.json.xz`` as it finishes
        (:func:`wheelloader.saved_loops.save_cycle`); an existing one (compressed or not) whose path equals the
        planned one is read instead of digging (resume).
    sigma_s : float, None or "plant"
        Gaussian filter of the plant's force before calibration and for the prediction error [s]; None: none;
        ``"plant"`` (default): the plant's ``filter_sigma_s`` where it has one, else 0.1 s.
    progress : callable, optional
        Called with one line per cycle.
    stale : {"error", "redig", "keep"}
        What to do with a saved cycle dug along another path than the one planned now (other settings or
        code, or another machine: the planner's choice can change with the last bits of the calibrated
        parameters): raise (default), dig again and replace it, or keep the saved cycle as the one that was
        dug (its plan's success, message, time and parameters are read from the log where it recorded
        them; the record's ``end`` says how far the plan made now lies from the path dug). Each is said in
        the progress line.

    Returns
    -------
    records, logs
        One :class:`~wheelloader.adaptation.CycleRecord` and the plant's raw :class:`CycleLog` per cycle.
    """
    if not isinstance(cycles, int) or isinstance(cycles, bool) or cycles < 1:
        raise WheelloaderError(f"cycles must be a positive integer, got {cycles!r}")
    start_cycle = getattr(plant, "start_cycle", None)
    if not (isinstance(pile, Pile) or (isinstance(pile, Mapping) and start_cycle is not None)):
        raise WheelloaderError(f"pile must be a Pile, got {type(pile).__name__}")
    if stale not in STALE_CHOICES:
        raise WheelloaderError(f"stale must be 'error', 'redig' or 'keep', got {stale!r}")
    if not callable(getattr(plant, "dig", None)):
        raise WheelloaderError(f"plant must have a dig(path, pile, soil, seed=...) method, got {type(plant).__name__}")
    sigma = getattr(plant, "filter_sigma_s", DEFAULT_FILTER["sigma_s"]) if sigma_s == PLANT_FILTER else sigma_s
    folder = None if cache is None else Path(cache)
    records: list[CycleRecord] = []
    logs: list[CycleLog] = []
    calibration = CalibrationStep(0.0, True, "prior parameters")
    for k in range(1, cycles + 1):
        if start_cycle is not None:
            pile = start_cycle(pile, soil, seed=seed, first=k == 1)
        if not isinstance(pile, Pile):
            raise WheelloaderError(f"plant {getattr(plant, 'name', plant)!r} gave no Pile to plan the cycle on")
        plan = strategy.plan(pile)
        cycle = _dig_or_resume(plant, strategy, plan, pile, soil, seed, folder, k, stale)
        log = cycle.log
        assert log is not None  # _dig_or_resume digs when nothing is saved
        if log.pile_after is None:
            raise WheelloaderError(f"plant {getattr(plant, 'name', plant)!r} did not return the carved pile "
                                   "(CycleLog.pile_after)")
        logs.append(log)
        smooth = log if sigma is None else filtered(log, sigma)
        records.append(_record(k, strategy, plan, cycle, smooth, calibration))
        if progress is not None:
            progress(progress_line(records[-1], cycle))
        pile = log.pile_after
        if k < cycles:
            truth = plant.true_soil(soil) if hasattr(plant, "true_soil") else _true_soil(soil)
            calibration = CalibrationStep.of(strategy.update(smooth, truth))
    return records, logs


def _dig_or_resume(plant: Plant, strategy: Strategy, plan: PlanOutcome, pile: Pile, soil: SoilParams | str,
                   seed: int, folder: Path | None, k: int, stale: str) -> SavedCycle:
    """Cycle ``k``: the saved one where it is of this plan (see ``stale``), else dug now (and saved)."""
    name = getattr(plant, "name", type(plant).__name__)
    record = PlanRecord(bool(plan.success), str(plan.message), float(plan.seconds), strategy.params)
    if plan.controller is not None and not getattr(plant, "accepts_controller", False):
        raise WheelloaderError(f"strategy {strategy.name!r} acts through a feedback controller (a policy or the "
                               f"MPC), which needs the env's observations: the {name!r} plant digs paths only")
    if plan.path is None:
        if plan.controller is None:
            raise WheelloaderError(f"strategy {strategy.name!r} gave neither a path nor a controller")
        if folder is not None:
            raise WheelloaderError(f"strategy {strategy.name!r} gives a controller, not a path: its cycles "
                                   "cannot be saved and resumed (cache=None)")
        cycle = SavedCycle(None, record, "path end")
    else:
        where = "" if folder is None else str(cycle_file(folder, k))
        # the plant's own saved cycle: no sign-convention heuristics (a bucket scraping the MPM bed has F_N < 0)
        cycle = resolve_saved_cycle(load_saved_cycle(folder, k, check=False), plan.path, stale, record, where)
    if cycle.log is not None:
        return cycle
    start = time.perf_counter()
    extra = {} if plan.controller is None else {"controller": plan.controller}
    log = plant.dig(plan.path, pile, soil, seed=seed, **extra)
    log.metadata.setdefault("plant_wall_s", time.perf_counter() - start)
    if plan.path is not None:
        log.metadata["planned_path_sha256"] = path_digest(plan.path)
        log.metadata["plan"] = cycle.plan.to_dict()
        if folder is not None:
            save_cycle(folder, k, log)
    return SavedCycle(log, cycle.plan, cycle.end, kept=False, replaced=cycle.replaced)


def _record(k: int, strategy: Strategy, plan: PlanOutcome, cycle: SavedCycle, smooth: CycleLog,
            calibration: CalibrationStep) -> CycleRecord:
    """The cycle's record: the plant's measurements (its own, or taken from the log) and the prediction of the
    parameters planned with."""
    log, planned = cycle.log, cycle.plan
    assert log is not None
    pred = predict(planned.params, smooth, options=strategy.model_options, fill=strategy.fill,
                   force_model=strategy.force_model, payload=strategy.payload)
    quality = pred.quality
    measured = log.metadata.get("measured")
    if isinstance(measured, Mapping):
        fill, fill_fraction = float(measured["fill_m3"]), float(measured["fill_fraction"])
        energy, stalled = float(measured["energy_J"]), bool(measured["stalled"])
        violations = int(measured["validity_violations"])
        end = cycle.end if cycle.end != "path end" else str(measured["end"])
    else:
        fill = float(log.fill_volume[-1]) if log.fill_volume is not None else math.nan
        fill_fraction, energy, stalled = fill / log.bucket.capacity, cycle_work(log), False
        in_soil = pred.state.depth > 0.0
        violations = int(np.count_nonzero((pred.forces.flags & ~FLAG_OUT_OF_SOIL) & in_soil))
        end = cycle.end
    if cycle.kept:
        path = str(log.metadata.get("path_name", plan.path.name if plan.path is not None else "controller"))
    else:
        path = plan.path.name if plan.path is not None else "controller"
    return CycleRecord(
        cycle=k, strategy=strategy.name, path=path, calibration_s=calibration.seconds, planning_s=planned.seconds,
        prediction_rmse_N=quality.rmse_r if quality else math.nan,
        prediction_rmse_percent=quality.percent_r if quality else math.nan,
        fill_m3=fill, fill_fraction=fill_fraction, energy_J=energy,
        energy_per_m3=energy / fill if fill > 0 else math.inf, stalled=stalled, validity_violations=violations,
        end=end, calibration_ok=calibration.ok, calibration_message=calibration.message, plan_ok=planned.ok,
        plan_message=planned.message, params=planned.params.to_dict())


def progress_line(r: CycleRecord, cycle: SavedCycle | None = None) -> str:
    """One line per cycle: fill, energy, the prediction error; whether it was resumed, kept or dug again; a
    failed calibration or plan."""
    notes = ""
    if cycle is not None and cycle.end == "resumed from cache":
        notes = " (resumed)"
    elif cycle is not None and cycle.kept:
        notes = f" ({cycle.end})"
    elif cycle is not None and cycle.replaced:
        notes = " (saved cycle of another plan dug again)"
    flag = "" if r.calibration_ok and r.plan_ok else "  [!] " + "; ".join(
        m for ok, m in ((r.calibration_ok, r.calibration_message), (r.plan_ok, r.plan_message)) if not ok)
    return (f"  {r.strategy:>7} cycle {r.cycle}: fill {r.fill_fraction:5.0%}, energy {r.energy_J / 1e3:6.2f} kJ, "
            f"{r.energy_per_m3 / 1e3:6.1f} kJ/m^3, prediction F_R RMSE {r.prediction_rmse_percent:5.1f} %"
            f"{notes}{flag}")


def _true_soil(soil: SoilParams | str) -> SoilParams:
    """What :meth:`Strategy.update` receives as the plant's truth when the plant does not say: on a plant that
    is not the model there is none in FEE terms; the soil's FEE parameters (a preset or the given ones) stand
    in, and only the simulation-world oracle reads them."""
    return preset(soil) if isinstance(soil, str) else soil


def plant_loop_unit(plant: Plant, strategy: str, soil: SoilParams | str, *, cycles: int, seed: int,
                    cache: Path | str | None, planner: bool = True, oracle_params: SoilParams | None = None,
                    stale: str = "error", sigma_s: float = DEFAULT_FILTER["sigma_s"],
                    failure_angle: str = "min_n_gamma", cut_angle: float | None = None,
                    fill_limit: float | None = None, heel_clearance: float | None = None,
                    end_blade_angle: float | None = None, curl_out_intervals: int = 0,
                    midpoints: bool | None = None, objective: str = "fill_energy",
                    lookahead: bool | str = False, rl_policy: str | None = None,
                    prior: str = "none", descend_clearance: float | None = None,
                    payload: Mapping[str, float] | None = None, force_model: str = "fee",
                    compiled: bool = False) -> dict[str, Any]:
    """One loop of :func:`run_loop` on the trapezoid pile as a unit of :mod:`wheelloader.sweep` (picklable
    arguments only).

    Builds the strategy by name in the process that runs it (``fixed``, ``ours``, ``paper``, or ``oracle``
    with ``oracle_params``, see :class:`Hindsight`) with the loop's default planner when ``planner`` is true,
    prints the loop's progress lines, and returns ``{"records": [CycleRecord.to_dict(), ...], "logs":
    [CycleLog, ...]}``. ``failure_angle``: the force-model rule for beta* of ``ours`` and ``oracle`` (their
    calibration, predictions and planner; :class:`~wheelloader.estimator.ModelOptions`); ``paper`` keeps the
    paper's model, ``fixed`` uses none. ``cut_angle``: the planner's opt-in cutting cone [rad], for every
    strategy that plans, ``fill_limit`` its largest planned fill as a share of the nominal capacity and
    ``heel_clearance`` its opt-in heel clearance [m] and ``end_blade_angle`` its opt-in end blade angle [rad],
    ``curl_out_intervals`` the plan's last intervals in which the bucket then curls out of the pile
    (:class:`~wheelloader.planner.PlannerOptions`), ``midpoints`` whether the plan's forces and validity are
    constrained at the intervals' midpoints too (default: :func:`~wheelloader.adaptation.default_planner`'s),
    ``objective`` the planner's objective (``"kept_per_energy"``: energy per m^3 of kept soil with the lift to the
    dump height, :mod:`wheelloader.planner.kept`) and ``lookahead`` whether each plan is chosen with the cycle
    after it in view (:func:`~wheelloader.planner.lookahead.plan_with_lookahead`; a setting of
    :func:`~wheelloader.adaptation.default_planner`); both for every strategy that plans. ``rl_policy``: the PPO
    ``.zip`` of the ``rl`` (a controller: the FEE env plant only) and ``rl_path``
    strategies (:class:`~wheelloader.adaptation.PolicyPath`: the policy's path in the FEE env, dug in the plant).
    ``prior``: the calibration prior of ``ours`` (a name of :data:`~wheelloader.loop_prior.LOOP_PRIORS`,
    centred on ``ours``' nominal soil). ``descend_clearance``: the planner's opt-in height above the surface
    above which the tip may not move down [m]; ``payload`` (a :class:`~wheelloader.estimator.PayloadOptions`'
    fields): the payload state of the kept objective, e.g. one with a ``curl_gain`` fitted to the plant's kept
    fill (``benchmarks/transfer.py``), for every strategy that plans; ``force_model``: the model ``ours``
    calibrates and plans with (:data:`~wheelloader.estimator.FORCE_MODELS`; under the payload models with
    ``payload``). ``compiled``: the planner's IPOPT derivatives as C compiled once per machine
    (:class:`~wheelloader.planner.PlannerOptions` ``compiled``: minutes of CPU per NLP the first time, the same
    plans). Every loop, with or without it, uses the libraries a compiled run left on this machine for its NLPs
    (:func:`~wheelloader.planner.nlp.compiled_if_present` is on while it runs; found by the NLP's key, never a
    stale one).
    """
    from wheelloader.adaptation import default_planner, make_strategy
    from wheelloader.planner.nlp import compiled_if_present

    model = ModelOptions(failure_angle=failure_angle)
    learning = strategy in ("ours", "oracle")
    kept_payload = as_payload(payload)
    plan = (default_planner(failure_angle=failure_angle if learning else "min_n_gamma", cut_angle=cut_angle,
                            fill_limit=fill_limit, heel_clearance=heel_clearance,
                            end_blade_angle=end_blade_angle, curl_out_intervals=curl_out_intervals,
                            midpoints=midpoints, objective=objective, lookahead=lookahead,
                            descend_clearance=descend_clearance, payload=kept_payload, compiled=compiled)
            if planner else None)
    ours_model = {} if force_model == "fee" else {"force_model": force_model, "payload": kept_payload}
    if strategy == "oracle":
        if oracle_params is None:
            raise WheelloaderError("plant_loop_unit: the oracle needs oracle_params (hindsight_parameters)")
        chosen: Strategy = Hindsight(oracle_params, plan, options=model)
    elif strategy == "ours" and (model.extra_terms or prior != "none" or ours_model):
        chosen = make_strategy(strategy, plan, ours_options={"prior": prior, **ours_model,
                                                             **({"options": model} if model.extra_terms else {})})
    else:
        chosen = make_strategy(strategy, plan, rl_policy=rl_policy)
    name = soil if isinstance(soil, str) else "custom soil"
    # the derivatives a compiled run left on this machine for the loop's NLPs, where there are any (found by the
    # NLP's key, never stale; the same plans), as wheelloader demo does
    found = compiled_if_present(True)
    try:
        records, logs = run_loop(plant, chosen, Pile.trapezoid(), soil, cycles=cycles, seed=seed, cache=cache,
                                 sigma_s=sigma_s, stale=stale,
                                 progress=lambda line: print(f"[{name}, seed {seed}]{line}", flush=True))
    finally:
        compiled_if_present(found)
    return {"records": [r.to_dict() for r in records], "logs": logs}


class Hindsight(Calibrating):
    """The hindsight oracle of a plant that is not the model: plan every cycle with one set of FEE
    parameters fitted afterwards to the plant's cycles of that soil (:func:`hindsight_parameters`); it
    learns nothing between cycles."""

    def __init__(self, params: SoilParams, planner: Any = None, rate: float = 60.0,
                 options: ModelOptions | None = None) -> None:
        super().__init__(params, "hindsight", planner, rate, name="oracle", options=options)

    def update(self, log: CycleLog, true_soil: SoilParams) -> CalibrationStep:
        return CalibrationStep(0.0, True, "hindsight parameters")


def hindsight_parameters(logs: list[CycleLog], method: str = "default",
                         sigma_s: float = DEFAULT_FILTER["sigma_s"],
                         options: ModelOptions | None = None) -> tuple[SoilParams, str]:
    """FEE parameters fitted to all ``logs`` of one soil (filtered), and how they were fitted (``options``:
    the force model's, e.g. its failure-angle rule; default the paper's model).

    Uses the several-cycle calibration ``calibrate([log, ...])`` where the estimator has it; otherwise the
    single-cycle fit, among one per log, whose F_R error summed over all logs is lowest (said in the
    returned text).
    """
    if not logs:
        raise WheelloaderError("hindsight_parameters needs at least one cycle log")
    options = DEFAULT_OPTIONS if options is None else options
    smooth = [filtered(lg, sigma_s) for lg in logs]
    try:
        result = calibrate(smooth, options=CalibrationOptions(method=method, model_options=options))
    except (TypeError, WheelloaderError) as exc:
        fallback = f"several-cycle calibration unavailable ({exc})"
    else:
        return result.params, f"one {method} fit to all {len(logs)} cycles"
    best, best_cost = None, math.inf
    for lg in smooth:
        candidate = calibrate(lg, options=CalibrationOptions(method=method, model_options=options)).params
        cost = sum(predict(candidate, other, options=options).quality.rmse_r ** 2 for other in smooth)
        if cost < best_cost:
            best, best_cost = candidate, cost
    assert best is not None  # logs is not empty
    return best, f"best of {len(logs)} single-cycle {method} fits over all cycles; {fallback}"
