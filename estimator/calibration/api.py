"""Calibrate the soil from one cycle: :func:`calibrate`, returning a :class:`~.result.Calibration`.

Methods
-------
``"varpro"`` (alias ``"default"``, the default)
    Our method (:mod:`wheelloader.estimator.calibration.varpro`): variable projection on
    the model's linear structure, a global grid over ``(phi, delta, n)``,
    analytic-Jacobian bounded least squares, optional warm start; with
    ``regularize=True`` the MAP estimate under a weak prior (mid-range or
    warm start, bound range / sqrt(12); noise per effective sample from the
    residual autocorrelation) resolves directions the cycle leaves undetermined.
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
from typing import Any

import numpy as np

from ..cyclelog import CycleLog
from ..errors import CalibrationError, ParameterError
from ..force_model import DEFAULT_OPTIONS, FLAG_TENSION, ModelOptions, soil_forces
from ..kinematics import DEFAULT_SLOPE_WINDOW, ContactState
from ..soil import PARAMETER_NAMES, SoilParams, as_soil, validate_bounds
from ..soil_vector import SOIL_VECTOR_NAMES as FIT_NAMES
from ..soil_vector import soil_from_vector, soil_vector, vector_bounds
from .bands import BandModel, residual_noise_model
from .fitmodel import MIN_SAMPLES, FitData
from .paper_methods import fit_multi_stage, fit_single_stage
from .priors import class_prior
from .result import Calibration, FitQuality, StageResult
from .uncertainty import analyse, integrated_autocorrelation_time
from .varpro import fit_varpro, refine
from .verdict import assess

#: Calibration methods, by what they are.
METHODS: tuple[str, ...] = ("varpro", "single-stage", "multi-stage")
#: Other accepted names of the methods (case-insensitive): ``"default"`` is the varpro method.
METHOD_ALIASES: dict[str, str] = {"default": "varpro", "single": "single-stage", "multi": "multi-stage"}
#: The method :func:`calibrate` uses unless told otherwise.
DEFAULT_METHOD = "varpro"
#: Largest number of in-soil samples a calibration fits. A longer log (about 3 hours of digging at 60 Hz,
#: or a log sampled far faster than the forces change) is fitted on a uniform subsample, every k-th
#: in-soil sample, and ``settings["decimation"]`` says so; memory then stays bounded (about 1.5 kB per
#: fitted sample at the peak, plus the log itself). The predicted forces cover every sample.
MAX_FIT_SAMPLES = 200_000
#: Samples per block when the fitted model's forces are evaluated along the whole log.
FORCE_CHUNK = 200_000

_log = logging.getLogger(__name__)


def canonical_method(method: str) -> str:
    """The name in :data:`METHODS` of a method or alias; :class:`CalibrationError` if unknown."""
    key = method.strip().lower() if isinstance(method, str) else None
    if key in METHODS:
        return key
    if key in METHOD_ALIASES:
        return METHOD_ALIASES[key]
    raise CalibrationError(f"unknown calibration method {method!r}; choose one of {list(METHODS)} "
                           f"(aliases {sorted(METHOD_ALIASES)})")


# ------------------------------------------------------------ calibrate
def _coerce_initial(initial: Any) -> SoilParams | None:
    if initial is None:
        return None
    if isinstance(initial, Calibration):
        return initial.params
    try:
        return as_soil(initial)
    except ParameterError as exc:
        raise CalibrationError(f"initial: {exc}") from None


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


def cycle_weights_for(count: int, forgetting: float | None = None,
                      cycle_weights: Any = None) -> list[float] | None:
    """Weights of ``count`` cycles (oldest first): ``forgetting ** (count - 1 - k)`` or the given list; None: all 1.

    A forgetting factor ``f`` in (0, 1] weighs the newest cycle 1, the one before ``f``, then ``f**2``,
    ...: the soil may drift between cycles, and old cycles then count less.
    """
    if forgetting is not None and cycle_weights is not None:
        raise CalibrationError("give forgetting or cycle_weights, not both")
    if forgetting is not None:
        if isinstance(forgetting, bool) or not isinstance(forgetting, (int, float)) or not 0.0 < forgetting <= 1.0:
            raise CalibrationError(f"forgetting must be a number in (0, 1], got {forgetting!r}")
        return [float(forgetting) ** (count - 1 - k) for k in range(count)]
    if cycle_weights is not None:
        try:
            w = [float(v) for v in cycle_weights]
        except (TypeError, ValueError):
            raise CalibrationError(f"cycle_weights must be {count} numbers > 0, got {cycle_weights!r}") from None
        if len(w) != count or not all(math.isfinite(v) and v > 0.0 for v in w):
            raise CalibrationError(f"cycle_weights must be {count} finite numbers > 0 (one per cycle), "
                                   f"got {cycle_weights!r}")
        return w
    return None


def calibrate(
    cycle: CycleLog | list[CycleLog],
    method: str = DEFAULT_METHOD,
    initial: Calibration | SoilParams | dict | str | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
    *,
    lam: float = 0.5,
    sigma: float = 3.0,
    grid: tuple[int, int, int] = (9, 9, 8),
    n_starts: int = 3,
    max_iter: int | None = None,
    options: ModelOptions = DEFAULT_OPTIONS,
    slope_window: float = DEFAULT_SLOPE_WINDOW,
    min_samples: int = MIN_SAMPLES,
    regularize: bool = False,
    forgetting: float | None = None,
    cycle_weights: list[float] | None = None,
    fill: str = "log",
    prior: str | dict | None = None,
    band_noise: str = "training",
) -> Calibration:
    """Calibrate the eight soil parameters from one cycle or from several.

    Parameters
    ----------
    cycle : CycleLog or list of CycleLog
        The measured cycle (path, F_T, F_N, pile at the start, bucket), or several cycles of the
        same soil and bucket, oldest first: one soil is fitted to all of them, each with the depth
        measured to its own pile surface (varpro method only). A list of one log gives exactly the
        one-log result.
    method : str
        ``"varpro"`` (our variable-projection method; alias ``"default"``),
        ``"single-stage"`` or ``"multi-stage"`` (the paper's, Section III).
    initial : Calibration, SoilParams, dict or str, optional
        Warm start: the previous cycle's result. The varpro method refines
        it as one more start (besides its grid search); the paper's methods
        start from it instead of the mid-range guess. Its share of k_c/b in
        K is kept when K is split into k_c, k_phi.
    bounds : dict, optional
        ``name -> (lower, upper)`` for some of the eight parameters; the
        others keep the paper's bounds (eq 19j). Equal bounds fix a parameter.
    lam : float
        Weight lambda of F_T in eq 19a (default 0.5; the multi-stage method
        uses its own stage weights).
    sigma : float
        Stage-2 Gaussian filter standard deviation [samples] (multi-stage).
    grid : tuple of int
        Grid sizes over (phi, delta, n) (varpro method).
    n_starts : int
        Grid local minima refined (varpro method).
    max_iter : int, optional
        Iteration limit: L-BFGS-B ``maxiter`` per stage for the paper's
        methods (default 1000, as the paper); residual evaluations per
        refinement for the varpro method (default 100).
    options : ModelOptions
        Force-model options.
    slope_window : float
        Half-width of the local slope chord [m].
    min_samples : int
        Smallest number of in-soil samples accepted.
    regularize : bool
        Varpro method only: after the exact least-squares fit, take the MAP
        estimate under a weak prior (mean ``initial`` or the mid-range of the
        bounds, standard deviation range / sqrt(12)) with the noise per
        independent sample estimated from the residuals' autocorrelation
        (:mod:`wheelloader.estimator.calibration.varpro`, step 6).
    forgetting : float, optional
        Several cycles: forgetting factor ``f`` in (0, 1]; cycle ``k`` of ``N`` (oldest first) weighs
        ``f ** (N - 1 - k)`` in the cost (the newest 1). Default: every cycle weighs 1.
    cycle_weights : list of float, optional
        Several cycles: explicit weight of each cycle's squared residuals (instead of ``forgetting``).
    fill : str
        Where the bucket load ``W_load`` comes from: ``"log"`` (default) the logged fill or load
        when the log has one, ``"model"`` the model's own bookkeeping (carving the pile along the
        path), the quantity a prediction of a new path has (:meth:`CycleLog.contact_state`).
    prior : str or dict, optional
        Varpro method: the MAP estimate under a literature prior of the soil class being dug,
        ``"granular"`` or ``"cohesive"`` (paper Tables A1, A2;
        :mod:`wheelloader.estimator.calibration.priors`), or ``{name: (low, high)}`` ranges of
        your own over the fit vector; it replaces the weak prior of ``regularize``.
    band_noise : str
        Residual noise model of the prediction band (:mod:`~.bands`): ``"training"`` (default) fits it to
        the training residuals; ``"cross-cycle"`` (several cycles) to the residuals of each cycle
        predicted by a fit on the others (leave one cycle out; one local refinement per cycle), the
        residuals of a path the fit has not seen.

    Returns
    -------
    Calibration
        With several cycles, ``quality`` covers the in-soil samples of all of them,
        ``predicted_*`` and ``in_soil`` are the cycles' series one after another, and
        ``settings["cycles"]`` holds each cycle's sample count, weight and F_R error, and the
        identifiability of the first 1, 2, ... cycles (:attr:`Calibration.identifiability_by_cycles`).

    Raises
    ------
    CalibrationError
        Unknown method, bad bounds or initial guess, NaN forces, too few
        samples, or no sample in soil.
    """
    method = canonical_method(method)
    logs = _coerce_cycles(cycle)
    weights_per_cycle = cycle_weights_for(len(logs), forgetting, cycle_weights)
    if len(logs) > 1 and method != "varpro":
        raise CalibrationError(f"calibration from several cycles ({len(logs)} given) is implemented for the varpro "
                               f"method only, not {method!r}")
    cycle = logs[0]
    if fill not in ("log", "model"):
        raise CalibrationError(f'fill must be "log" or "model", got {fill!r}')
    if options.extra_terms and method != "varpro":
        raise CalibrationError(f"the paper's methods fit the paper's model only; the opt-in term(s) "
                               f"{list(options.extra_terms)} need the varpro method")
    try:
        bnds = validate_bounds({} if bounds is None else bounds)
    except ParameterError as exc:
        raise CalibrationError(str(exc)) from None
    if not (isinstance(lam, (int, float)) and 0.0 <= lam <= 1.0):
        raise CalibrationError(f"lam must be in [0, 1], got {lam!r}")
    if not (isinstance(sigma, (int, float)) and math.isfinite(sigma) and sigma >= 0.0):
        raise CalibrationError(f"sigma must be a finite number of samples >= 0, got {sigma!r}")
    if max_iter is not None and not (isinstance(max_iter, int) and max_iter >= 1):
        raise CalibrationError(f"max_iter must be a positive integer, got {max_iter!r}")
    if not (isinstance(grid, (tuple, list)) and len(grid) == 3
            and all(isinstance(g, (int, np.integer)) and not isinstance(g, bool) and g >= 1 for g in grid)):
        raise CalibrationError(f"grid must be three positive integers (points over phi, delta, n), got {grid!r}")
    if not (isinstance(n_starts, int) and not isinstance(n_starts, bool) and n_starts >= 1):
        raise CalibrationError(f"n_starts must be a positive integer, got {n_starts!r}")
    if not (isinstance(min_samples, int) and not isinstance(min_samples, bool) and min_samples >= 1):
        raise CalibrationError(f"min_samples must be a positive integer, got {min_samples!r}")
    if not isinstance(regularize, bool):
        raise CalibrationError(f"regularize must be True or False, got {regularize!r}")
    if band_noise not in ("training", "cross-cycle"):
        raise CalibrationError(f'band_noise must be "training" or "cross-cycle", got {band_noise!r}')
    literature = prior
    prior_moments = None if literature is None else class_prior(literature)
    if literature is not None and canonical_method(method) != "varpro":
        raise CalibrationError("a literature prior needs the varpro method")
    if method == "multi-stage" and sigma > len(cycle):  # (one cycle: the paper's methods take no list)
        # gaussian_filter1d's kernel spans 8 sigma: a sigma of 1e9 samples asked for 60 GiB
        raise CalibrationError(f"sigma = {sigma:g} samples is wider than the cycle ({len(cycle)} samples); "
                               "the stage-2 filter needs sigma <= the number of samples")
    start = _coerce_initial(initial)
    bucket = cycle.bucket
    b = bucket.edge_thickness
    states = [log.contact_state(slope_window, fill) for log in logs]
    parts = []
    for k, (log, st) in enumerate(zip(logs, states, strict=True)):
        try:
            parts.append(FitData.from_state(st, log.tangential, log.normal, log.bucket, options, min_samples))
        except CalibrationError as exc:
            raise CalibrationError(f"cycle {k}: {exc}" if len(logs) > 1 else str(exc)) from None
    data = parts[0] if len(logs) == 1 else FitData.concat(parts, weights_per_cycle)
    state = states[0]
    lo, hi = vector_bounds(bnds, b)
    settings: dict[str, Any] = {"lambda": lam}
    if options != DEFAULT_OPTIONS or fill != "log":  # recorded so that predict() uses the same model
        settings["model_options"] = dataclasses.asdict(options)
        settings["fill"] = fill
    stride = -(-len(data) // MAX_FIT_SAMPLES)
    if stride > 1:
        _log.warning("calibrate: %d in-soil samples exceed MAX_FIT_SAMPLES = %d; fitting every %d-th sample",
                     len(data), MAX_FIT_SAMPLES, stride)
        settings["decimation"] = {"stride": stride, "in_soil_samples": len(data), "max_fit_samples": MAX_FIT_SAMPLES}
        data = data.every(stride)
    _log.info("calibrate: method %s on %d in-soil samples of %d", method, len(data), len(cycle))

    t0 = time.perf_counter()
    stages: list[StageResult] = []
    njev = 0
    if method == "varpro":
        settings.update(grid=list(grid), n_starts=n_starts, max_nfev=max_iter or 100,
                        regularize=regularize or prior_moments is not None)
        if literature is not None:
            settings["literature_prior"] = (literature if isinstance(literature, str)
                                            else {k: list(v) for k, v in literature.items()})
        x0 = None if start is None else soil_vector(start, b)
        fit = fit_varpro(data, lo, hi, lam, x0, tuple(int(g) for g in grid), n_starts, max_iter or 100,
                         regularize=regularize or prior_moments is not None, prior_moments=prior_moments)
        if fit.prior is not None:
            settings["prior"] = {"mean": fit.prior.mean, "scale": fit.prior.scale, "nu": fit.prior.nu,
                                 "autocorrelation_time": fit.tau, "exact_fit": fit.exact,
                                 "exact_fit_cost": fit.exact_cost}
        x = fit.x
        nfev, njev = fit.evaluations.nfev, fit.evaluations.njev
        success = fit.success and fit.status > 0
        status, message = fit.status, fit.message
        if fit.status == 0:
            message = f"did not converge: {fit.message}"
        stages.append(_stage("grid", data, fit.grid_best, lam, fit.grid_time, int(np.prod(grid)), True,
                             f"best of {int(np.prod(grid))} grid points (projected cost {fit.grid_cost:.4g})"))
        stages.append(_stage("refine", data, x, lam, fit.refine_time, sum(r.nfev for r in fit.refinements),
                             success, f"{len(fit.refinements)} start(s); best: {message}"))
    else:
        maxiter = max_iter or 1000
        if method == "single-stage":
            pf = fit_single_stage(data, bnds, start, maxiter)
        else:
            settings["sigma"] = sigma
            pf = fit_multi_stage(data, bnds, start, sigma, cycle.normal, maxiter)
        theta = pf.theta
        x = soil_vector(theta, b)
        nfev = sum(s.nfev for s in pf.stages)
        success = all(s.success for s in pf.stages)
        failed = [s for s in pf.stages if not s.success]
        status = failed[0].status if failed else 0
        message = "; ".join(f"{s.name}: {s.message}" for s in pf.stages)
        if failed:
            message = "did not converge: " + message
        settings.update(maxiter=maxiter, initial_guess="given" if start is not None else "mid-range of bounds")
        for s in pf.stages:
            stages.append(_paper_stage(s, data, b))
    time_s = time.perf_counter() - t0
    _log.info("calibrate: %s fit in %.2f s (%d model evaluations)", method, time_s, nfev)

    # Soil parameters: the paper's methods estimate k_c, k_phi directly; varpro splits K.
    if method == "varpro":
        soil = soil_from_vector(x, b, bnds, start)
    else:
        soil = SoilParams.from_array(np.clip(pf.theta, [bnds[k][0] for k in PARAMETER_NAMES],
                                             [bnds[k][1] for k in PARAMETER_NAMES]))
    if len(logs) == 1:
        pred_t, pred_n, flags = _forces_along(soil, state, bucket, options)
        in_soil = np.zeros(len(cycle), dtype=bool)
        in_soil[data.index] = True
        at_t, at_n, at_flags = pred_t[data.index], pred_n[data.index], flags[data.index]
    else:
        along = [_forces_along(soil, st, log.bucket, options) for log, st in zip(logs, states, strict=True)]
        masks = []
        for k, log in enumerate(logs):
            m = np.zeros(len(log), dtype=bool)
            m[data.index[data.cycle == k]] = True
            masks.append(m)
        pred_t, pred_n, flags = (np.concatenate([a[j] for a in along]) for j in range(3))
        in_soil = np.concatenate(masks)
        at_t = np.concatenate([a[0][data.index[data.cycle == k]] for k, a in enumerate(along)])
        at_n = np.concatenate([a[1][data.index[data.cycle == k]] for k, a in enumerate(along)])
        at_flags = np.concatenate([a[2][data.index[data.cycle == k]] for k, a in enumerate(along)])
    quality = FitQuality.from_forces(data.y_t, data.y_n, at_t, at_n)
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
    force_scale = float(np.mean(np.hypot(data.y_t, data.y_n)))
    unc = analyse(jac, resid, x, lo, hi, force_scale)
    obs_r, fit_r = np.hypot(data.y_t, data.y_n), np.hypot(at_t, at_n)
    if band_noise == "cross-cycle" and len(logs) > 1:
        obs_r, fit_r = _held_out_forces(parts, weights_per_cycle, x, lo, hi, lam, max_iter or 100)
        settings["band_noise"] = "cross-cycle"
    sigma_0, relative = residual_noise_model(obs_r, fit_r)
    settings["band_model"] = BandModel(unc.covariance, integrated_autocorrelation_time(obs_r - fit_r), sigma_0,
                                       relative).to_dict()
    if len(logs) > 1:
        settings["cycles"] = _cycles_report(logs, data, weights_per_cycle, at_t, at_n, jac, resid, x, lo, hi,
                                            force_scale)
    tension = int(np.count_nonzero(at_flags & FLAG_TENSION))
    warnings = assess(success=bool(success), obs_t=data.y_t, obs_n=data.y_n, pred_t=at_t,
                      pred_n=at_n, percent_r=quality.percent_r, names=FIT_NAMES, values=x,
                      lower=lo, upper=hi)
    return Calibration(soil, method, float(x[5]), cost, bool(success), int(status), message, int(nfev), int(njev),
                       time_s, quality, stages, unc, start, bnds, pred_t, pred_n, in_soil, tension, settings, warnings)


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
        part = ContactState(state.depth[sl], state.rho[sl], state.alpha[sl], state.blade_length[sl],
                            state.fill_volume[sl], load, None, acc, vel)
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
