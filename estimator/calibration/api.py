"""Calibrate the soil from one cycle or several: :func:`calibrate`, returning a :class:`~.result.Calibration`.

Settings: :class:`~.options.CalibrationOptions` (one frozen dataclass, validated when made). Each method
has one fit function returning a :class:`MethodFit` (:data:`FIT_FUNCTIONS`); :func:`calibrate` runs the
same path for one cycle and for several.

Methods
-------
``"varpro"`` (alias ``"default"``, the default)
    Our method (:mod:`wheelloader.estimator.calibration.varpro`): variable projection on the model's linear
    structure, a global grid over ``(phi, delta, n)``, analytic-Jacobian bounded least squares, optional warm
    start; with ``regularize=True`` the MAP estimate under a weak prior (mid-range or warm start, bound range /
    sqrt(12); noise per effective sample from the residual autocorrelation) resolves directions the cycle leaves
    undetermined. ``force_model="fee-learned"``: :mod:`.learned_fit`.
``"single-stage"``, ``"multi-stage"`` (aliases ``"single"``, ``"multi"``)
    The paper's baselines (:mod:`wheelloader.estimator.calibration.paper_methods`),
    L-BFGS-B with finite differences, as in Section III.

Fit quality: :mod:`wheelloader.estimator.calibration.result`; fit verdict:
:mod:`wheelloader.estimator.calibration.verdict`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import check_range
from ..cyclelog import CycleLog
from ..errors import CalibrationError
from ..force_model import DEFAULT_OPTIONS, FLAG_TENSION, ModelOptions, soil_forces
from ..force_models import DEFAULT_FORCE_MODEL, cycle_contact_state
from ..kinematics import ContactState
from ..plausibility import plausibility_warnings
from ..soil import PARAMETER_NAMES, SoilParams
from ..soil_vector import SOIL_VECTOR_NAMES as FIT_NAMES
from ..soil_vector import soil_from_vector, soil_vector, vector_bounds
from .bands import BandModel, residual_noise_model
from .fitmodel import FitData
from .learned_fit import calibrate_learned
from .options import DEFAULT_METHOD, METHOD_ALIASES, METHODS, CalibrationOptions, canonical_method
from .paper_methods import fit_multi_stage, fit_single_stage
from .priors import class_prior
from .result import Calibration, FitQuality, StageResult
from .uncertainty import analyse, integrated_autocorrelation_time
from .varpro import fit_varpro, refine
from .verdict import FitWarning, assess

__all__ = ["DEFAULT_METHOD", "FIT_FUNCTIONS", "METHODS", "METHOD_ALIASES", "CalibrationOptions", "MethodFit",
           "calibrate", "canonical_method", "cycle_weights_for", "fit_paper_method", "fit_varpro_method"]

#: Largest number of in-soil samples a calibration fits. A longer log (about 3 hours of digging at 60 Hz,
#: or a log sampled far faster than the forces change) is fitted on a uniform subsample, every k-th
#: in-soil sample, and ``settings["decimation"]`` says so; memory then stays bounded (about 1.5 kB per
#: fitted sample at the peak, plus the log itself). The predicted forces cover every sample.
MAX_FIT_SAMPLES = 200_000
#: Samples per block when the fitted model's forces are evaluated along the whole log.
FORCE_CHUNK = 200_000
#: The keyword arguments of the old signature ``calibrate(cycle, method, initial, bounds, *, lam, ...)``,
#: still accepted (with a :class:`DeprecationWarning`) for one release; ``options`` was the model options.
LEGACY_POSITIONAL = ("method", "initial", "bounds")
LEGACY_RENAMED = {"options": "model_options"}

_log = logging.getLogger(__name__)


# ------------------------------------------------------------ calibrate
def _coerce_cycles(cycle: Any) -> list[CycleLog]:
    """One log or a non-empty sequence of logs, as a list (oldest first)."""
    if isinstance(cycle, CycleLog):
        return [cycle]
    if isinstance(cycle, (list, tuple)):
        if not cycle:
            raise CalibrationError("cycle: an empty list of cycle logs; give at least one")
        for k, log in enumerate(cycle):
            if not isinstance(log, CycleLog):
                raise CalibrationError(f"cycle[{k}] must be a CycleLog, got {type(log).__name__}")
        return list(cycle)
    raise CalibrationError(f"cycle must be a CycleLog or a list of CycleLogs, got {type(cycle).__name__}")


def cycle_weights_for(count: int, forgetting: float | None = None, cycle_weights: Any = None) -> list[float] | None:
    """Weights of ``count`` cycles (oldest first): ``forgetting ** (count - 1 - k)`` or the given list; None: all 1.

    A forgetting factor ``f`` in (0, 1] weighs the newest cycle 1, the one before ``f``, then ``f**2``,
    ...: the soil may drift between cycles, and old cycles then count less.
    """
    if forgetting is not None and cycle_weights is not None:
        raise CalibrationError("give forgetting or cycle_weights, not both")
    if forgetting is not None:
        check_range("forgetting", forgetting, 0.0, 1.0, low_open=True, error=CalibrationError)
        return [float(forgetting) ** (count - 1 - k) for k in range(count)]
    if cycle_weights is not None:
        try:
            w = [float(v) for v in cycle_weights]
        except (TypeError, ValueError):
            raise CalibrationError(f"cycle_weights must be {count} numbers > 0, got {cycle_weights!r}") from None
        if len(w) != count or not all(math.isfinite(v) and v > 0.0 for v in w):
            raise CalibrationError(f"cycle_weights must be {count} numbers > 0 (one per cycle), got {cycle_weights!r}")
        return w
    return None


def _resolve_call(cycles: Any, options: Any, args: tuple, kwargs: dict) -> tuple[Any, CalibrationOptions]:
    """The cycles and :class:`CalibrationOptions` of a call, from ``options=`` or (deprecated) the old arguments."""
    if not args and not kwargs and (options is None or isinstance(options, CalibrationOptions)):
        return cycles, CalibrationOptions() if options is None else options
    if options is None and len(args) == 1 and isinstance(args[0], CalibrationOptions) and not kwargs:
        return cycles, args[0]
    if isinstance(options, CalibrationOptions) or any(isinstance(a, CalibrationOptions) for a in args):
        raise TypeError("calibrate: give the settings either as options=CalibrationOptions(...) or as the "
                        "deprecated keyword arguments, not both")
    if len(args) > len(LEGACY_POSITIONAL):
        raise TypeError(f"calibrate() takes at most {len(LEGACY_POSITIONAL) + 1} positional arguments "
                        f"({len(args) + 1} given)")
    legacy = dict(zip(LEGACY_POSITIONAL, args, strict=False))
    for name, value in kwargs.items():
        if name in legacy:
            raise TypeError(f"calibrate() got multiple values for argument {name!r}")
        legacy[name] = value
    if "cycle" in legacy:  # the old name of the first argument
        if cycles is not None:
            raise TypeError("calibrate() got multiple values for argument 'cycles'")
        cycles = legacy.pop("cycle")
    if options is not None:  # the old signature's options= was the force-model options
        legacy["options"] = options
    fields = {f.name for f in dataclasses.fields(CalibrationOptions)}
    mapped = {LEGACY_RENAMED.get(k, k): v for k, v in legacy.items()}
    unknown = sorted(k for k in mapped if k not in fields)
    if unknown:
        raise TypeError(f"calibrate() got unexpected keyword argument(s) {unknown}")
    warnings.warn("calibrate(cycle, method, ..., lam=..., options=ModelOptions(...)) is deprecated and will be "
                  "removed in the next release; pass calibrate(cycles, options=CalibrationOptions(...)) "
                  "(the model options as CalibrationOptions(model_options=...))", DeprecationWarning, stacklevel=3)
    return cycles, CalibrationOptions(**mapped)


@dataclass(frozen=True)
class MethodFit:
    """Outcome of one method's fit (:func:`fit_varpro_method`, :func:`fit_paper_method`).

    Attributes
    ----------
    x : numpy.ndarray
        The fit vector (:data:`FIT_NAMES`) at the solution.
    soil : SoilParams
        The calibrated soil.
    success : bool
        Whether every solver run converged.
    status : int
        Status of the solver run that decides ``success``.
    message : str
        Solver message(s).
    nfev, njev : int
        Model and analytic-Jacobian evaluations.
    time_s : float
        Wall time of the fit [s].
    stages : list of StageResult
        Per-stage parameters, RMSE and timings.
    settings : dict
        The method's settings, recorded in :attr:`Calibration.settings`.
    """

    x: np.ndarray
    soil: SoilParams
    success: bool
    status: int
    message: str
    nfev: int
    njev: int
    time_s: float
    stages: list[StageResult]
    settings: dict[str, Any]


def fit_varpro_method(data: FitData, cycle: CycleLog, opts: CalibrationOptions, lo: np.ndarray,
                      hi: np.ndarray) -> MethodFit:
    """The ``"varpro"`` method on ``data`` (:func:`~.varpro.fit_varpro`) as a :class:`MethodFit`."""
    b = data.edge_thickness
    settings: dict[str, Any] = {"grid": list(opts.grid), "n_starts": opts.n_starts, "max_nfev": opts.max_nfev,
                                "regularize": opts.map_estimate}
    if opts.prior is not None:
        settings["literature_prior"] = (opts.prior if isinstance(opts.prior, str)
                                        else {k: list(v) for k, v in opts.prior.items()})
    t0 = time.perf_counter()
    x0 = None if opts.initial is None else soil_vector(opts.initial, b)
    moments = None if opts.prior is None else class_prior(opts.prior)
    if opts.held is not None:
        cycles = 1 if data.cycle is None else int(np.max(data.cycle)) + 1
        settings["held"] = opts.held.to_dict() | {"free": list(opts.held.free(cycles))}
        moments = opts.held.apply(cycles, lo, hi)[2]
    fit = fit_varpro(data, lo, hi, opts.lam, x0, opts.grid, opts.n_starts, opts.max_nfev,
                     regularize=opts.regularize or moments is not None, prior_moments=moments)
    if fit.prior is not None:
        settings["prior"] = {"mean": fit.prior.mean, "scale": fit.prior.scale, "nu": fit.prior.nu,
                             "autocorrelation_time": fit.tau, "exact_fit": fit.exact, "exact_fit_cost": fit.exact_cost}
    success = fit.success and fit.status > 0
    message = f"did not converge: {fit.message}" if fit.status == 0 else fit.message
    points = int(np.prod(opts.grid))
    stages = [_stage("grid", data, fit.grid_best, opts.lam, fit.grid_time, points, True,
                     f"best of {points} grid points (projected cost {fit.grid_cost:.4g})"),
              _stage("refine", data, fit.x, opts.lam, fit.refine_time, sum(r.nfev for r in fit.refinements),
                     success, f"{len(fit.refinements)} start(s); best: {message}")]
    time_s = time.perf_counter() - t0
    return MethodFit(x=fit.x, soil=soil_from_vector(fit.x, b, opts.bounds, opts.initial), success=success,
                     status=fit.status, message=message, nfev=fit.evaluations.nfev, njev=fit.evaluations.njev,
                     time_s=time_s, stages=stages, settings=settings)


def fit_paper_method(data: FitData, cycle: CycleLog, opts: CalibrationOptions, lo: np.ndarray,
                     hi: np.ndarray) -> MethodFit:
    """The paper's ``"single-stage"`` or ``"multi-stage"`` method (:mod:`~.paper_methods`) as a :class:`MethodFit`."""
    settings: dict[str, Any] = {}
    t0 = time.perf_counter()
    if opts.method == "single-stage":
        pf = fit_single_stage(data, opts.bounds, opts.initial, opts.maxiter)
    else:
        settings["sigma"] = opts.sigma
        pf = fit_multi_stage(data, opts.bounds, opts.initial, opts.sigma, cycle.normal, opts.maxiter)
    b = data.edge_thickness
    failed = [s for s in pf.stages if not s.success]
    message = "; ".join(f"{s.name}: {s.message}" for s in pf.stages)
    settings.update(maxiter=opts.maxiter, initial_guess="given" if opts.initial is not None else "mid-range of bounds")
    stages = [_paper_stage(s, data, b) for s in pf.stages]
    time_s = time.perf_counter() - t0
    # the paper's methods estimate k_c, k_phi directly (varpro splits K)
    soil = SoilParams.from_array(np.clip(pf.theta, [opts.bounds[k][0] for k in PARAMETER_NAMES],
                                         [opts.bounds[k][1] for k in PARAMETER_NAMES]))
    return MethodFit(x=soil_vector(pf.theta, b), soil=soil, success=not failed,
                     status=failed[0].status if failed else 0,
                     message=("did not converge: " + message) if failed else message,
                     nfev=sum(s.nfev for s in pf.stages), njev=0, time_s=time_s, stages=stages, settings=settings)


#: The fit function of each method: ``(data, first cycle, options, lower, upper) -> MethodFit``.
FIT_FUNCTIONS = {"varpro": fit_varpro_method, "single-stage": fit_paper_method, "multi-stage": fit_paper_method}


def calibrate(cycles: CycleLog | list[CycleLog] | None = None, *legacy_args: Any,
              options: CalibrationOptions | None = None, **legacy_kwargs: Any) -> Calibration:
    """Calibrate the eight soil parameters from one cycle or from several.

    Parameters
    ----------
    cycles : CycleLog or list of CycleLog
        The measured cycle (path, F_T, F_N, pile at the start, bucket), or several cycles of the same soil
        and bucket, oldest first: one soil is fitted to all of them, each with the depth measured to its own
        pile surface (varpro method only). A list of one log gives exactly the one-log result.
    options : CalibrationOptions, optional
        Every setting (method, warm start, bounds, weights, force model, ...); default the varpro method's.
    *legacy_args, **legacy_kwargs
        Deprecated (one release): the old signature ``calibrate(cycle, method, initial, bounds, *, lam,
        sigma, grid, n_starts, max_iter, options, slope_window, min_samples, regularize, forgetting,
        cycle_weights, fill, prior, band_noise)``, where ``options`` was the :class:`ModelOptions`. They
        map one to one onto :class:`CalibrationOptions` (``options`` onto ``model_options``; ``cycle=`` onto
        ``cycles``) with a :class:`DeprecationWarning`.

    Returns
    -------
    Calibration
        With several cycles, ``quality`` covers the in-soil samples of all of them, ``predicted_*`` and
        ``in_soil`` are the cycles' series one after another, and ``settings["cycles"]`` holds each cycle's
        sample count, weight and F_R error, and the identifiability of the first 1, 2, ... cycles
        (:attr:`Calibration.identifiability_by_cycles`).

    Raises
    ------
    CalibrationError
        Bad settings (:class:`CalibrationOptions`), NaN forces, too few samples, or no sample in soil.
    """
    cycles, opts = _resolve_call(cycles, options, legacy_args, legacy_kwargs)
    logs = _coerce_cycles(cycles)
    if opts.force_model == "fee-learned":  # the payload FEE fitted to the forces minus the learned correction
        return calibrate_learned(logs, opts, calibrate)
    weights = cycle_weights_for(len(logs), opts.forgetting, opts.cycle_weights)
    if len(logs) > 1 and opts.method != "varpro":
        raise CalibrationError(f"calibration from several cycles ({len(logs)} given) is implemented for the varpro "
                               f"method only, not {opts.method!r}")
    if opts.method == "multi-stage" and opts.sigma > len(logs[0]):  # (one cycle: the paper's methods take no list)
        # gaussian_filter1d's kernel spans 8 sigma: a sigma of 1e9 samples asked for 60 GiB
        raise CalibrationError(f"sigma = {opts.sigma:g} samples is wider than the cycle ({len(logs[0])} samples); "
                               "the stage-2 filter needs sigma <= the number of samples")
    states = [cycle_contact_state(log, opts.force_model, opts.payload, opts.slope_window, opts.fill) for log in logs]
    parts = [_fit_data(log, st, opts, k if len(logs) > 1 else None) for k, (log, st) in enumerate(zip(logs, states,
                                                                                                      strict=True))]
    data = parts[0] if len(logs) == 1 else FitData.concat(parts, weights)
    lo, hi = vector_bounds(opts.bounds, logs[0].bucket.edge_thickness)
    lo, hi = (lo, hi) if opts.held is None else opts.held.apply(len(logs), lo, hi)[:2]  # identify.py
    settings = _model_settings(opts)
    data = _decimated(data, settings)
    _log.info("calibrate: method %s on %d in-soil samples of %d", opts.method, len(data), len(logs[0]))
    fit = FIT_FUNCTIONS[opts.method](data, logs[0], opts, lo, hi)
    settings.update(fit.settings)
    _log.info("calibrate: %s fit in %.2f s (%d model evaluations)", opts.method, fit.time_s, fit.nfev)
    pred_t, pred_n, flags, in_soil, fitted = _forces_along_cycles(fit.soil, logs, states, data, opts.model_options)
    at_t, at_n, at_flags = pred_t[fitted], pred_n[fitted], flags[fitted]
    quality = FitQuality.from_forces(data.y_t, data.y_n, at_t, at_n)
    cost, resid, jac = _weighted_residuals(data, fit.x, opts.lam)
    force_scale = float(np.mean(np.hypot(data.y_t, data.y_n)))
    unc = analyse(jac, resid, fit.x, lo, hi, force_scale)
    obs_r, fit_r = np.hypot(data.y_t, data.y_n), np.hypot(at_t, at_n)
    if opts.band_noise == "cross-cycle" and len(logs) > 1:
        obs_r, fit_r = _held_out_forces(parts, weights, fit.x, lo, hi, opts.lam, opts.max_nfev)
        settings["band_noise"] = "cross-cycle"
    sigma_0, relative = residual_noise_model(obs_r, fit_r)
    settings["band_model"] = BandModel(unc.covariance, integrated_autocorrelation_time(obs_r - fit_r), sigma_0,
                                       relative, opts.band_scale).to_dict()
    if len(logs) > 1:
        settings["cycles"] = _cycles_report(logs, data, weights, at_t, at_n, jac, resid, fit.x, lo, hi, force_scale)
    warns = assess(success=bool(fit.success), obs_t=data.y_t, obs_n=data.y_n, pred_t=at_t, pred_n=at_n,
                   percent_r=quality.percent_r, names=FIT_NAMES, values=fit.x, lower=lo, upper=hi)
    warns += [FitWarning("implausible_log", w) for log in logs for w in plausibility_warnings(log)]
    return Calibration(params=fit.soil, method=opts.method, sinkage_modulus=float(fit.x[5]), cost=cost,
                       success=bool(fit.success), status=int(fit.status), message=fit.message, nfev=int(fit.nfev),
                       njev=int(fit.njev), time_s=fit.time_s, quality=quality, stages=fit.stages, uncertainty=unc,
                       initial=opts.initial, bounds=dict(opts.bounds), predicted_tangential=pred_t,
                       predicted_normal=pred_n, in_soil=in_soil, tension_samples=int(np.count_nonzero(
                           at_flags & FLAG_TENSION)), settings=settings, warnings=warns)


def _model_settings(opts: CalibrationOptions) -> dict[str, Any]:
    """The settings a calibration records first: lambda, and the model, so that predict() uses the same one."""
    settings: dict[str, Any] = {"lambda": opts.lam}
    if opts.model_options != DEFAULT_OPTIONS or opts.fill != "log":
        settings["model_options"] = dataclasses.asdict(opts.model_options)
        settings["fill"] = opts.fill
    if opts.force_model != DEFAULT_FORCE_MODEL:
        settings["force_model"] = opts.force_model
        settings["payload"] = opts.payload.to_dict()
    return settings


def _fit_data(log: CycleLog, state: ContactState, opts: CalibrationOptions, k: int | None) -> FitData:
    """The in-soil samples of one cycle (``k``: its index among several, named in an error)."""
    try:
        return FitData.from_state(state, log.tangential, log.normal, log.bucket, opts.model_options,
                                  opts.min_samples)
    except CalibrationError as exc:
        raise CalibrationError(f"cycle {k}: {exc}" if k is not None else str(exc)) from None


def _decimated(data: FitData, settings: dict[str, Any]) -> FitData:
    """``data``, or every k-th sample of it when it holds more than :data:`MAX_FIT_SAMPLES` (recorded in settings)."""
    stride = -(-len(data) // MAX_FIT_SAMPLES)
    if stride <= 1:
        return data
    _log.warning("calibrate: %d in-soil samples exceed MAX_FIT_SAMPLES = %d; fitting every %d-th sample",
                 len(data), MAX_FIT_SAMPLES, stride)
    settings["decimation"] = {"stride": stride, "in_soil_samples": len(data), "max_fit_samples": MAX_FIT_SAMPLES}
    return data.every(stride)


def _weighted_residuals(data: FitData, x: np.ndarray, lam: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Eq 19a's cost with lambda = 0.5, and the lambda-weighted residual vector and Jacobian at ``x``."""
    f_t, f_n, jt, jn = data.forces_and_jacobian(x)
    wt, wn = math.sqrt(lam), math.sqrt(1.0 - lam)
    if data.weight is None:
        resid = np.concatenate([wt * (f_t - data.y_t), wn * (f_n - data.y_n)])
        jac = np.vstack([wt * jt, wn * jn])
        cost = float(0.5 * np.sum((f_t - data.y_t) ** 2) + 0.5 * np.sum((f_n - data.y_n) ** 2))
    else:
        rw = data.root_weight
        resid = np.concatenate([rw * wt * (f_t - data.y_t), rw * wn * (f_n - data.y_n)])
        jac = np.vstack([rw[:, None] * wt * jt, rw[:, None] * wn * jn])
        cost = float(0.5 * np.sum(data.weight * (f_t - data.y_t) ** 2)
                     + 0.5 * np.sum(data.weight * (f_n - data.y_n) ** 2))
    return cost, resid, jac


def _forces_along_cycles(soil: SoilParams, logs: list[CycleLog], states: list[ContactState], data: FitData,
                         options: ModelOptions) -> tuple[np.ndarray, ...]:
    """``(F_T, F_N, flags, in_soil, fitted)`` of the model along every cycle, one after another.

    ``in_soil`` marks the fitted samples (:attr:`FitData.index` of each cycle), ``fitted`` their positions
    in the joined series, in the order of ``data``'s samples.
    """
    along, masks, fitted, offset = [], [], [], 0
    for k, (log, st) in enumerate(zip(logs, states, strict=True)):
        along.append(_forces_along(soil, st, log.bucket, options))
        index = data.index if data.cycle is None else data.index[data.cycle == k]
        mask = np.zeros(len(log), dtype=bool)
        mask[index] = True
        masks.append(mask)
        fitted.append(index + offset)
        offset += len(log)
    if len(logs) == 1:
        return (*along[0], masks[0], fitted[0])
    return (*(np.concatenate([a[j] for a in along]) for j in range(3)), np.concatenate(masks),
            np.concatenate(fitted))


def _held_out_forces(parts: list[FitData], weights: list[float] | None, x: np.ndarray, lo: np.ndarray,
                     hi: np.ndarray, lam: float, max_nfev: int) -> tuple[np.ndarray, np.ndarray]:
    """Observed and predicted F_R of each cycle from a fit on the other cycles (leave one cycle out).

    Each refit is a local refinement from the joint solution ``x`` (no grid search); the residuals are
    those of cycles the fit did not see, the honest residuals of a prediction of a new path.
    """
    obs, pred = [], []
    for j, held in enumerate(parts):
        rest = [p for k, p in enumerate(parts) if k != j]
        w = None if weights is None else [v for k, v in enumerate(weights) if k != j]
        data = rest[0] if len(rest) == 1 and w is None else FitData.concat(rest, w)
        xj = refine(data, x, lo, hi, lam, max_nfev=max_nfev).x
        f_t, f_n, _ = held.forces(xj)
        obs.append(np.hypot(held.y_t, held.y_n))
        pred.append(np.hypot(f_t, f_n))
    return np.concatenate(obs), np.concatenate(pred)


def _cycles_report(logs: list[CycleLog], data: FitData, weights: list[float] | None, at_t: np.ndarray,
                   at_n: np.ndarray, jac: np.ndarray, resid: np.ndarray, x: np.ndarray, lo: np.ndarray,
                   hi: np.ndarray, force_scale: float) -> dict[str, Any]:
    """Per cycle of a several-cycle calibration: samples, weight, fit, and what the first 1, 2, ... cycles determined.

    The identifiability of the first ``j`` cycles is the analysis of
    :func:`~wheelloader.estimator.calibration.uncertainty.analyse` on their rows of the weighted
    Jacobian at the final solution (so it shows what each added cycle contributes, not the
    solution each prefix alone would have given).
    """
    per_cycle = []
    for k, log in enumerate(logs):
        sel = data.cycle == k
        q = FitQuality.from_forces(data.y_t[sel], data.y_n[sel], at_t[sel], at_n[sel])
        per_cycle.append({"name": log.path.name, "samples": int(np.count_nonzero(sel)),
                          "weight": 1.0 if weights is None else float(weights[k]), "rmse": q.to_dict()})
    rows = np.concatenate([data.cycle, data.cycle])
    prefixes = []
    for j in range(1, len(logs) + 1):
        sel = rows < j
        u = analyse(jac[sel], resid[sel], x, lo, hi, force_scale)
        prefixes.append({"cycles": j, "std_errors": {n: (float(v) if np.isfinite(v) else None)
                                                     for n, v in zip(FIT_NAMES, u.std_errors, strict=True)},
                         "relative_std_errors": {n: (float(v) if np.isfinite(v) else None)
                                                 for n, v in zip(FIT_NAMES, u.relative_std_errors, strict=True)},
                         "status": dict(u.status), "weak_combinations": u.weak_combinations})
    return {"count": len(logs), "per_cycle": per_cycle, "identifiability": prefixes}


def _forces_along(soil: SoilParams, state: ContactState, bucket, options: ModelOptions):
    """``(F_T, F_N, flags)`` of the model along the whole log, in blocks of :data:`FORCE_CHUNK` samples."""
    n = len(state)
    if n <= FORCE_CHUNK:
        f = soil_forces(soil, state, bucket, options)
        return f.tangential, f.normal, f.flags
    f_t, f_n, flags = np.empty(n), np.empty(n), np.empty(n, dtype=np.int64)
    for s in range(0, n, FORCE_CHUNK):
        sl = slice(s, min(s + FORCE_CHUNK, n))
        load = None if state.measured_load is None else np.asarray(state.measured_load)[sl]
        acc = None if state.acceleration is None else state.acceleration[sl]
        vel = None if state.velocity is None else state.velocity[sl]
        cv = None if state.carried_volume is None else state.carried_volume[sl]
        part = ContactState(state.depth[sl], state.rho[sl], state.alpha[sl], state.blade_length[sl],
                            state.fill_volume[sl], load, None, acc, vel, cv)
        f = soil_forces(soil, part, bucket, options)
        f_t[sl], f_n[sl], flags[sl] = f.tangential, f.normal, f.flags
    return f_t, f_n, flags


def _stage(name: str, data: FitData, x: np.ndarray, lam: float, time_s: float, nfev: int, success: bool,
           message: str) -> StageResult:
    f_t, f_n, _ = data.forces(x)
    q = FitQuality.from_forces(data.y_t, data.y_n, f_t, f_n)
    cost = float(lam * np.sum((f_t - data.y_t) ** 2) + (1 - lam) * np.sum((f_n - data.y_n) ** 2))
    params = {n: float(v) for n, v in zip(FIT_NAMES, x, strict=True)}
    return StageResult(name, params, cost, {"F_T": [q.rmse_t, q.percent_t], "F_N": [q.rmse_n, q.percent_n],
                                           "F_R": [q.rmse_r, q.percent_r]}, time_s, nfev, success, message)


def _paper_stage(stage, data: FitData, b: float) -> StageResult:
    """Per-stage RMSE as the paper's Table 3: stage 1 and 3 on F_T, stage 2 on the FEE force F."""
    params = {n: float(v) for n, v in zip(stage.names, stage.x, strict=True)}
    rmse: dict[str, list[float]] = {}
    if stage.name == "stage 2":
        obs, pred = stage.extra["observed"], stage.extra["prediction"]
        filt = stage.extra["filtered"]
        r = float(np.sqrt(np.mean((obs - pred) ** 2)))
        rf = float(np.sqrt(np.mean((filt - pred) ** 2)))
        scale = float(np.mean(np.abs(obs)))
        rmse["F"] = [r, 100.0 * r / scale if scale > 0 else float("inf")]
        rmse["F_filtered"] = [rf, 100.0 * rf / scale if scale > 0 else float("inf")]
    elif stage.name in ("stage 1", "stage 3"):
        pred = stage.extra["prediction"]
        r = float(np.sqrt(np.mean((data.y_t - pred) ** 2)))
        scale = float(np.mean(np.abs(data.y_t)))
        rmse["F_T"] = [r, 100.0 * r / scale if scale > 0 else float("inf")]
    else:
        x = stage.x
        f_t, f_n, _ = data.forces(soil_vector(x, b))
        q = FitQuality.from_forces(data.y_t, data.y_n, f_t, f_n)
        rmse = {"F_T": [q.rmse_t, q.percent_t], "F_N": [q.rmse_n, q.percent_n], "F_R": [q.rmse_r, q.percent_r]}
    return StageResult(stage.name, params, stage.cost, rmse, stage.time_s, stage.nfev, stage.success, stage.message)
