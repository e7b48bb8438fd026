"""The adaptation loop on any reference plant: plan, dig in the plant, calibrate, plan again.

:func:`wheelloader.adaptation.run_loop` closes the loop in the FEE env, i.e. in the model's own world.
:func:`run_plant_loop` closes it on anything with the reference-plant interface
(:class:`wheelloader.references.Plant`: ``dig(path, pile, soil, seed) -> CycleLog`` with the carved pile in
``pile_after``): the plane-strain MPM continuum (:class:`~wheelloader.references.mpm.MPMPlant`), or the FEE
env itself through :class:`~wheelloader.references.fee_env.FEEEnvPlant`. The strategies are those of
:mod:`wheelloader.adaptation`; every metric is measured by the plant, the same way for every strategy:

* energy: the work the bucket does on the soil along the path, ``-sum F . v dt`` with ``F`` the plant's
  bucket force (F_T, F_N turned back into the world frame) and ``v`` the tip velocity
  (:func:`wheelloader.references.metrics.cycle_work`); the carried load's weight is in ``F``, so lifting
  it is counted;
* fill: the plant's soil inside the bucket at the end of the path;
* next-cycle prediction error: the F_R RMSE of the parameters the strategy planned with against the
  plant's force, filtered with the references' Gaussian (σ 0.1 s), over the in-soil samples.

Between cycles the strategies calibrate on the filtered log. Each cycle's log is saved as it finishes
(``cache``), and a loop that finds a saved cycle whose path equals the one it planned reads it instead of
digging again: an interrupted run resumes where it stopped.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.adaptation import Calibrating, CycleRecord, Strategy
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
)
from wheelloader.estimator.cyclelog import find_cycle_log
from wheelloader.planner import MODEL_FALLBACK_NAME
from wheelloader.references.filtering import DEFAULT_FILTER, filtered
from wheelloader.references.metrics import cycle_work
from wheelloader.references.plant import Plant


def _cached(cache: Path | None, key: str) -> CycleLog | None:
    if cache is None:
        return None
    saved = find_cycle_log(cache, key)
    return None if saved is None else CycleLog.load(saved)


def path_distance(a: Any, b: Any) -> float:
    """Largest distance [m] between the tip positions of two paths, each resampled at the other's times
    (over the shorter duration); inf when their durations differ by more than one sample."""
    ta, tb = np.asarray(a.t, dtype=float), np.asarray(b.t, dtype=float)
    step = max(float(np.median(np.diff(ta))) if ta.size > 1 else 0.0,
               float(np.median(np.diff(tb))) if tb.size > 1 else 0.0)
    if abs(ta[-1] - tb[-1]) > step + 1e-12:
        return math.inf
    t = np.union1d(ta, tb)
    t = t[t <= min(ta[-1], tb[-1])]
    dx = np.interp(t, ta, a.x) - np.interp(t, tb, b.x)
    dz = np.interp(t, ta, a.z) - np.interp(t, tb, b.z)
    return float(np.max(np.hypot(dx, dz)))


def path_digest(path: Any) -> str:
    """SHA-256 of a path's samples (t, x, z, blade angle): which plan a saved cycle was dug for."""
    h = hashlib.sha256()
    for arr in (path.t, path.x, path.z, path.blade_angle):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class _PlanRecord:
    """What the loop records of the plan a cycle was dug along."""

    ok: bool
    message: str
    seconds: float
    params: SoilParams


def _resolve_saved_cycle(log: CycleLog | None, digest: str, path: Any, stale: str, record: _PlanRecord,
                         where: str) -> tuple[CycleLog | None, _PlanRecord, str, bool, bool]:
    """What to do with a saved cycle (``log``, None when there is none) for the plan made now (``path``, its
    ``digest``): ``(log to use or None to dig, the plan's record, the cycle record's end, kept, replaced)``.

    A saved cycle of the same plan is resumed; one dug along another path is refused (``stale="error"``),
    dug again (``"redig"``) or kept as the cycle dug (``"keep"``; the plan's record is then read from the
    log where it recorded it, see :func:`run_plant_loop`).
    """
    if log is None:
        return None, record, "path end", False, False
    if log.metadata.get("planned_path_sha256") == digest:
        return log, record, "resumed from cache", False, False
    if stale == "error":
        raise WheelloaderError(f"{where} was dug along another path than the one planned now (other settings, "
                               "code or machine); use another cache folder, remove it, or resume with "
                               "stale='keep' or 'redig'")
    if stale == "redig":
        return None, record, "path end", False, True
    end = f"kept saved cycle (path planned now differs by {path_distance(path, log.path):.3g} m)"
    saved = log.metadata.get("plan")
    dug_name = log.metadata.get("path_name")
    if isinstance(saved, dict):
        record = _PlanRecord(bool(saved["ok"]), str(saved["message"]), float(saved["seconds"]),
                             SoilParams.from_dict(saved["params"]))
    elif dug_name is not None and dug_name != path.name:
        # the log predates plan records: what was dug tells whether its plan passed the check
        record = replace(record, ok=dug_name != MODEL_FALLBACK_NAME,
                         message=f"kept cycle dug along the {dug_name!r} path (its plan's record not saved)")
    else:
        end += "; its plan's record is that of the plan made now"
    return log, record, end, True, False


def run_plant_loop(plant: Plant, strategy: Strategy, pile: Pile, soil: SoilParams | str, *, cycles: int = 5,
                   seed: int = 0, cache: str | Path | None = None, sigma_s: float = DEFAULT_FILTER["sigma_s"],
                   progress: Callable[[str], None] | None = None, stale: str = "error"
                   ) -> tuple[list[CycleRecord], list[CycleLog]]:
    """Run ``cycles`` cycles of ``strategy`` in ``plant``, each on the pile the previous one carved.

    Parameters
    ----------
    plant : Plant
        The plant that digs (its ``dig`` must return the carved surface in ``pile_after``).
    strategy : Strategy
        A strategy of :mod:`wheelloader.adaptation` that plans paths (a policy strategy, which needs the
        env's observations, cannot run on a plant).
    pile : Pile
        Surface before the first cycle.
    soil : SoilParams or str
        The plant's soil (hidden from the strategy; the plant documents which fields it uses).
    cycles : int
        Cycles to dig (>= 1).
    seed : int
        Seed of the plant (packing, jitter).
    cache : str or Path, optional
        Folder where each cycle's log is saved as ``cycle<k>.csv.xz`` + ``.json.xz`` (xz-compressed; a
        saved ``cycle<k>.csv`` is read too) as it finishes; an existing
        one whose path equals the planned one is read instead of digging (resume).
    sigma_s : float
        Gaussian filter of the plant's force before calibration and for the prediction error [s].
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
    if not isinstance(pile, Pile):
        raise WheelloaderError(f"pile must be a Pile, got {type(pile).__name__}")
    if stale not in ("error", "redig", "keep"):
        raise WheelloaderError(f"stale must be 'error', 'redig' or 'keep', got {stale!r}")
    if not callable(getattr(plant, "dig", None)):
        raise WheelloaderError(f"plant must have a dig(path, pile, soil, seed=...) method, got {type(plant).__name__}")
    folder = None if cache is None else Path(cache)
    if folder is not None:
        folder.mkdir(parents=True, exist_ok=True)
    records: list[CycleRecord] = []
    logs: list[CycleLog] = []
    calib = (0.0, True, "prior parameters")
    for k in range(1, cycles + 1):
        plan = strategy.plan(pile)
        if plan.path is None:
            raise WheelloaderError(f"strategy {strategy.name!r} gives a controller, not a path: it needs the env's "
                                   "observations and cannot dig in a reference plant")
        record = _PlanRecord(bool(plan.success), str(plan.message), float(plan.seconds), strategy.params)
        digest = path_digest(plan.path)
        saved = _cached(folder, f"cycle{k}")
        where = "" if saved is None else str(find_cycle_log(folder, f"cycle{k}"))
        log, record, end, kept, replaced = _resolve_saved_cycle(saved, digest, plan.path, stale, record, where)
        resumed = log is not None
        if log is None:
            start = time.perf_counter()
            log = plant.dig(plan.path, pile, soil, seed=seed)
            log.metadata.setdefault("plant_wall_s", time.perf_counter() - start)
            log.metadata["planned_path_sha256"] = digest
            log.metadata["plan"] = {"ok": record.ok, "message": record.message, "seconds": record.seconds,
                                    "params": record.params.to_dict()}
            if folder is not None:
                log.save(folder / f"cycle{k}.csv.xz", overwrite=True)
                for plain in (folder / f"cycle{k}.csv", folder / f"cycle{k}.json"):  # a replaced uncompressed one
                    plain.unlink(missing_ok=True)
        if log.pile_after is None:
            raise WheelloaderError(f"plant {getattr(plant, 'name', plant)!r} did not return the carved pile "
                                   "(CycleLog.pile_after)")
        logs.append(log)
        smooth = filtered(log, sigma_s)
        pred = predict(record.params, smooth, options=strategy.model_options, fill=strategy.fill)
        quality = pred.quality
        in_soil = pred.state.depth > 0.0
        violations = int(np.count_nonzero((pred.forces.flags & ~FLAG_OUT_OF_SOIL) & in_soil))
        fill = float(log.fill_volume[-1]) if log.fill_volume is not None else math.nan
        energy = cycle_work(log)
        records.append(CycleRecord(
            cycle=k, strategy=strategy.name, calibration_s=calib[0],
            path=str(log.metadata.get("path_name", plan.path.name)) if kept else plan.path.name,
            planning_s=record.seconds,
            prediction_rmse_N=quality.rmse_r if quality else math.nan,
            prediction_rmse_percent=quality.percent_r if quality else math.nan,
            fill_m3=fill, fill_fraction=fill / log.bucket.capacity, energy_J=energy,
            energy_per_m3=energy / fill if fill > 0 else math.inf, stalled=False,
            validity_violations=violations, end=end,
            calibration_ok=calib[1], calibration_message=calib[2], plan_ok=record.ok,
            plan_message=record.message, params=record.params.to_dict()))
        if progress is not None:
            r = records[-1]
            progress(f"  {r.strategy:>7} cycle {k}: fill {r.fill_fraction:5.0%}, energy {r.energy_J / 1e3:6.2f} kJ, "
                     f"{r.energy_per_m3 / 1e3:6.1f} kJ/m^3, prediction F_R RMSE {r.prediction_rmse_percent:5.1f} %"
                     + (" (resumed)" if resumed and not kept else "")
                     + (f" ({end})" if kept else "")
                     + (" (saved cycle of another plan dug again)" if replaced else ""))
        pile = log.pile_after
        if k < cycles:
            calib = strategy.update(smooth, _true_soil(soil))
    return records, logs


def _true_soil(soil: SoilParams | str) -> SoilParams:
    """What :meth:`Strategy.update` receives as the plant's truth: on a plant that is not the model there is
    none in FEE terms; the soil's FEE parameters (a preset or the given ones) stand in, and only the
    simulation-world oracle reads them."""
    from wheelloader.estimator import preset

    return preset(soil) if isinstance(soil, str) else soil



def plant_loop_unit(plant: Plant, strategy: str, soil: SoilParams | str, *, cycles: int, seed: int,
                    cache: Path | str | None, planner: bool = True, oracle_params: SoilParams | None = None,
                    stale: str = "error", sigma_s: float = DEFAULT_FILTER["sigma_s"],
                    failure_angle: str = "min_n_gamma", cut_angle: float | None = None,
                    fill_limit: float | None = None, heel_clearance: float | None = None,
                    end_blade_angle: float | None = None, curl_out_intervals: int = 0,
                    midpoints: bool | None = None) -> dict[str, Any]:
    """One loop of :func:`run_plant_loop` as a unit of :mod:`wheelloader.sweep` (picklable arguments only).

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
    constrained at the intervals' midpoints too (default: :func:`~wheelloader.adaptation.default_planner`'s).
    """
    from wheelloader.adaptation import default_planner, make_strategy

    model = ModelOptions(failure_angle=failure_angle)
    learning = strategy in ("ours", "oracle")
    plan = (default_planner(failure_angle=failure_angle if learning else "min_n_gamma", cut_angle=cut_angle,
                            fill_limit=fill_limit, heel_clearance=heel_clearance,
                            end_blade_angle=end_blade_angle, curl_out_intervals=curl_out_intervals,
                            midpoints=midpoints)
            if planner else None)
    if strategy == "oracle":
        if oracle_params is None:
            raise WheelloaderError("plant_loop_unit: the oracle needs oracle_params (hindsight_parameters)")
        chosen: Strategy = Hindsight(oracle_params, plan, options=model)
    elif strategy == "ours" and model.extra_terms:
        chosen = make_strategy(strategy, plan, ours_options={"options": model})
    else:
        chosen = make_strategy(strategy, plan)
    name = soil if isinstance(soil, str) else "custom soil"
    records, logs = run_plant_loop(plant, chosen, Pile.trapezoid(), soil, cycles=cycles, seed=seed, cache=cache,
                                   sigma_s=sigma_s, stale=stale,
                                   progress=lambda line: print(f"[{name}, seed {seed}]{line}", flush=True))
    return {"records": [r.to_dict() for r in records], "logs": logs}


class Hindsight(Calibrating):
    """The hindsight oracle of a plant that is not the model: plan every cycle with one set of FEE
    parameters fitted afterwards to the plant's cycles of that soil (:func:`hindsight_parameters`); it
    learns nothing between cycles."""

    def __init__(self, params: SoilParams, planner: Any = None, rate: float = 60.0,
                 options: ModelOptions | None = None) -> None:
        super().__init__(params, "hindsight", planner, rate, name="oracle", options=options)

    def update(self, log: CycleLog, true_soil: SoilParams) -> tuple[float, bool, str]:
        return 0.0, True, "hindsight parameters"


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
