"""Calibrate the soil from one cycle: :func:`calibrate` and its :class:`Calibration` result.

Methods
-------
``"default"`` (alias ``"varpro"``)
    Our method (:mod:`wheelloader.estimator.calibration.varpro`): variable projection on
    the model's linear structure, a global grid over ``(phi, delta, n)``,
    analytic-Jacobian bounded least squares, optional warm start; with
    ``regularize=True`` the MAP estimate under a weak prior (mid-range or
    warm start, bound range / sqrt(12); noise per effective sample from the
    residual autocorrelation) resolves directions the cycle leaves undetermined.
``"single-stage"``, ``"multi-stage"``
    The paper's baselines (:mod:`wheelloader.estimator.calibration.paper_methods`),
    L-BFGS-B with finite differences, as in Section III.

Fit quality (same definition for every method)
----------------------------------------------
RMSE of F_T, F_N and F_R = sqrt(F_T^2 + F_N^2) over the **in-soil samples**
(depth > 0 to the surface at the start of the cycle; out of soil every
method predicts exactly zero, so those samples would only dilute the
figure), in N, and as a percentage of the **mean observed magnitude** of the
same component over the same samples: ``100 * RMSE_X / mean(|X_obs|)``.
The cost is eq 19a with lambda = 0.5 over the same samples.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..cyclelog import CycleLog
from ..errors import CalibrationError, ParameterError
from ..force_model import DEFAULT_OPTIONS, FLAG_TENSION, ModelOptions, soil_forces
from ..kinematics import DEFAULT_SLOPE_WINDOW
from ..soil import PARAMETER_NAMES, SoilParams, as_soil, validate_bounds
from ..soil_vector import SOIL_VECTOR_NAMES as FIT_NAMES
from ..soil_vector import soil_from_vector, soil_vector, vector_bounds
from .fitmodel import MIN_SAMPLES, FitData
from .paper_methods import fit_multi_stage, fit_single_stage
from .uncertainty import Uncertainty, analyse
from .varpro import fit_default
from .verdict import FitWarning, assess

#: Calibration methods.
METHODS: tuple[str, ...] = ("default", "single-stage", "multi-stage")
_ALIASES = {"default": "default", "varpro": "default", "single-stage": "single-stage", "single": "single-stage",
            "multi-stage": "multi-stage", "multi": "multi-stage"}


# ----------------------------------------------------------------- quality
@dataclass(frozen=True)
class FitQuality:
    """RMSE of F_T, F_N, F_R over the in-soil samples [N] and in % of the mean observed magnitude."""

    rmse_t: float
    rmse_n: float
    rmse_r: float
    percent_t: float
    percent_n: float
    percent_r: float
    samples: int

    @classmethod
    def from_forces(cls, obs_t, obs_n, pred_t, pred_n) -> FitQuality:
        """Quality of a prediction on the given (in-soil) samples."""
        obs_t, obs_n, pred_t, pred_n = (np.asarray(v, float) for v in (obs_t, obs_n, pred_t, pred_n))
        obs_r, pred_r = np.hypot(obs_t, obs_n), np.hypot(pred_t, pred_n)
        out = []
        for o, p in ((obs_t, pred_t), (obs_n, pred_n), (obs_r, pred_r)):
            out.append(float(np.sqrt(np.mean((o - p) ** 2))))
        pct = []
        for o, r in zip((obs_t, obs_n, obs_r), out, strict=True):
            scale = float(np.mean(np.abs(o)))
            pct.append(100.0 * r / scale if scale > 0 else float("inf"))
        return cls(*out, *pct, int(obs_t.size))

    def to_dict(self) -> dict[str, Any]:
        """``{"F_T": [N, %], "F_N": [...], "F_R": [...], "samples": n}``."""
        return {"F_T": [self.rmse_t, self.percent_t], "F_N": [self.rmse_n, self.percent_n],
                "F_R": [self.rmse_r, self.percent_r], "samples": self.samples}

    def describe(self) -> str:
        """One line: RMSE in N and %."""
        return (f"RMSE F_T {self.rmse_t:.1f} N ({self.percent_t:.2f} %), F_N {self.rmse_n:.1f} N "
                f"({self.percent_n:.2f} %), F_R {self.rmse_r:.1f} N ({self.percent_r:.2f} %) over {self.samples} "
                "in-soil samples")


@dataclass(frozen=True)
class StageResult:
    """One stage of a calibration (per-stage parameters, fit, time)."""

    name: str
    parameters: dict[str, float]
    cost: float
    rmse: dict[str, list[float]]
    time_s: float
    nfev: int
    success: bool
    message: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping."""
        return {"name": self.name, "parameters": dict(self.parameters), "cost": self.cost, "rmse": self.rmse,
                "time_s": self.time_s, "nfev": self.nfev, "success": self.success, "message": self.message}


# -------------------------------------------------------------- result
@dataclass(eq=False)
class Calibration:
    """Result of :func:`calibrate` (pickle-able; JSON via :meth:`to_dict` / :meth:`save_json`).

    Attributes
    ----------
    params : SoilParams
        Calibrated soil. ``k_c``/``k_phi`` are a documented split of the
        identified ``K`` (see :attr:`sinkage_modulus` and :attr:`uncertainty`).
    method : str
        ``"default"``, ``"single-stage"`` or ``"multi-stage"``.
    sinkage_modulus : float
        Identified ``K = k_c / b + k_phi`` [N/m^(n+2)] (eq 15).
    cost : float
        Eq 19a with lambda = 0.5 at ``params`` over the in-soil samples [N^2].
    success, status, message
        Convergence of the optimiser(s); ``success=False`` whenever a stage
        stopped on an iteration/evaluation limit or failed.
    nfev, njev : int
        Model evaluations (parameter sets at which forces were computed,
        counting every grid point and every finite-difference probe) and
        analytic Jacobian evaluations.
    time_s : float
        Wall time of the optimisation [s] (excludes kinematics and the
        uncertainty analysis).
    quality : FitQuality
        RMSE on the training cycle (module docstring).
    stages : list of StageResult
        Per-stage parameters, RMSE and timings.
    uncertainty : Uncertainty
        Covariance, standard errors and identifiability.
    initial : SoilParams or None
        Initial guess / warm start used.
    bounds : dict
        Bounds of the eight parameters.
    predicted_tangential, predicted_normal : numpy.ndarray
        Model forces along the whole cycle [N].
    in_soil : numpy.ndarray
        Boolean mask of the samples used.
    tension_samples : int
        In-soil samples where the FEE force is clamped at 0 at ``params``.
    settings : dict
        Method settings (lambda, sigma, grid, ...).
    warnings : list of FitWarning
        Why the data may not have determined the soil (forces near zero,
        constant or implausible forces, large error, little variation
        explained, parameters on bounds, too few samples in soil, no
        convergence); see :mod:`wheelloader.estimator.calibration.verdict`.
        Empty for a trustworthy fit.
    """

    params: SoilParams
    method: str
    sinkage_modulus: float
    cost: float
    success: bool
    status: int
    message: str
    nfev: int
    njev: int
    time_s: float
    quality: FitQuality
    stages: list[StageResult]
    uncertainty: Uncertainty
    initial: SoilParams | None
    bounds: dict[str, tuple[float, float]]
    predicted_tangential: np.ndarray = field(repr=False)
    predicted_normal: np.ndarray = field(repr=False)
    in_soil: np.ndarray = field(repr=False)
    tension_samples: int = 0
    settings: dict[str, Any] = field(default_factory=dict)
    warnings: list[FitWarning] = field(default_factory=list)

    @property
    def trustworthy(self) -> bool:
        """True when no :attr:`warnings` fired: the data could determine the soil (``success`` is separate)."""
        return not self.warnings

    @property
    def identifiability(self) -> dict[str, Any]:
        """The identifiability report (see :mod:`wheelloader.estimator.calibration.uncertainty`)."""
        return self.uncertainty.to_dict()

    @property
    def std_errors(self) -> dict[str, float]:
        """Standard errors of :data:`FIT_NAMES` (NaN for parameters on a bound)."""
        return {n: float(v) for n, v in zip(FIT_NAMES, self.uncertainty.std_errors, strict=True)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable ``{"soil": {8 params}, "calibration": {...}}`` (the params.json format)."""
        return {
            "soil": self.params.to_dict(),
            "calibration": {
                "method": self.method,
                "sinkage_modulus_K": self.sinkage_modulus,
                "cost": self.cost,
                "success": self.success,
                "trustworthy": self.trustworthy,
                "warnings": [w.to_dict() for w in self.warnings],
                "status": self.status,
                "message": self.message,
                "nfev": self.nfev,
                "njev": self.njev,
                "time_s": self.time_s,
                "rmse": self.quality.to_dict(),
                "rmse_definition": "over in-soil samples; % = 100 * RMSE / mean(|observed|) of the same component",
                "stages": [s.to_dict() for s in self.stages],
                "identifiability": self.uncertainty.to_dict(),
                "initial": None if self.initial is None else self.initial.to_dict(),
                "bounds": {k: list(v) for k, v in self.bounds.items()},
                "tension_samples": self.tension_samples,
                "settings": self.settings,
            },
        }

    def save_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as strict JSON to ``path`` (NaN and infinities become ``null``)."""
        path = Path(path)
        path.write_text(json.dumps(jsonable(self.to_dict()), indent=1, allow_nan=False))
        return path

    def summary(self) -> str:
        """Multi-line human-readable summary."""
        flag = "converged" if self.success else "NOT CONVERGED"
        verdict = "trustworthy" if self.trustworthy else "NOT TRUSTWORTHY"
        lines = [f"method {self.method}: {flag} ({self.message}); {self.time_s * 1e3:.1f} ms, "
                 f"{self.nfev} model evaluations, cost {self.cost:.4g} N^2",
                 f"  fit verdict: {verdict}" + "".join(f"\n    warning {w}" for w in self.warnings),
                 "  " + self.quality.describe(), self.params.describe(),
                 f"  K = k_c/b + k_phi = {self.sinkage_modulus:.6g} N/m^(n+2)"]
        for s in self.stages:
            lines.append(f"  stage {s.name}: {s.time_s * 1e3:.1f} ms, {s.nfev} evals, "
                         + ", ".join(f"{k} {v[0]:.1f} N ({v[1]:.2f} %)" for k, v in s.rmse.items()))
        lines.append("identifiability:")
        lines.append(self.uncertainty.describe())
        if self.tension_samples:
            lines.append(f"  note: the FEE force is clamped at 0 on {self.tension_samples} samples")
        return "\n".join(lines)


def jsonable(obj: Any) -> Any:
    """``obj`` with NumPy arrays and scalars as lists and numbers, and NaN/infinities as ``None`` (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if obj is None or isinstance(obj, (str, int, float, bool)):
        return obj
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def load_params(source: str | Path | dict | Calibration | SoilParams) -> SoilParams:
    """Soil parameters from a params.json path, a ``{"soil": {...}}`` or bare 8-parameter dict, a preset name,
    a :class:`Calibration` or :class:`SoilParams`."""
    if isinstance(source, Calibration):
        return source.params
    if isinstance(source, SoilParams):
        return source
    if isinstance(source, dict):
        data = source.get("soil", source) if "soil" in source else source
        return SoilParams.from_dict(data)
    path = Path(source)
    if path.suffix.lower() == ".json" or path.exists():
        if not path.exists():
            raise FileNotFoundError(2, "No such file", str(path))
        try:
            data = json.loads(path.read_text(encoding="utf-8-sig"))
        except (json.JSONDecodeError, UnicodeDecodeError, IsADirectoryError) as exc:
            raise ParameterError(f"{path}: not a valid JSON file ({exc})") from None
        if not isinstance(data, dict):
            raise ParameterError(f"{path}: expected a JSON object with the soil parameters")
        try:
            return load_params(data)
        except ParameterError as exc:
            raise ParameterError(f"{path}: {exc}") from None
    return as_soil(str(source))


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


def calibrate(
    cycle: CycleLog,
    method: str = "default",
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
) -> Calibration:
    """Calibrate the eight soil parameters from one cycle.

    Parameters
    ----------
    cycle : CycleLog
        The measured cycle (path, F_T, F_N, pile at the start, bucket).
    method : str
        ``"default"`` (our variable-projection method), ``"single-stage"`` or
        ``"multi-stage"`` (the paper's, Section III).
    initial : Calibration, SoilParams, dict or str, optional
        Warm start: the previous cycle's result. The default method refines
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
        Grid sizes over (phi, delta, n) (default method).
    n_starts : int
        Grid local minima refined (default method).
    max_iter : int, optional
        Iteration limit: L-BFGS-B ``maxiter`` per stage for the paper's
        methods (default 1000, as the paper); residual evaluations per
        refinement for the default method (default 100).
    options : ModelOptions
        Force-model options.
    slope_window : float
        Half-width of the local slope chord [m].
    min_samples : int
        Smallest number of in-soil samples accepted.
    regularize : bool
        Default method only: after the exact least-squares fit, take the MAP
        estimate under a weak prior (mean ``initial`` or the mid-range of the
        bounds, standard deviation range / sqrt(12)) with the noise per
        independent sample estimated from the residuals' autocorrelation
        (:mod:`wheelloader.estimator.calibration.varpro`, step 6).

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        Unknown method, bad bounds or initial guess, NaN forces, too few
        samples, or no sample in soil.
    """
    if not isinstance(method, str) or method.strip().lower() not in _ALIASES:
        raise CalibrationError(f"unknown calibration method {method!r}; choose one of {list(METHODS)}")
    method = _ALIASES[method.strip().lower()]
    if not isinstance(cycle, CycleLog):
        raise CalibrationError(f"cycle must be a CycleLog, got {type(cycle).__name__}")
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
    prior = _coerce_initial(initial)
    bucket = cycle.bucket
    b = bucket.edge_thickness
    state = cycle.contact_state(slope_window)
    data = FitData.from_state(state, cycle.tangential, cycle.normal, bucket, options, min_samples)
    lo, hi = vector_bounds(bnds, b)

    t0 = time.perf_counter()
    stages: list[StageResult] = []
    njev = 0
    settings: dict[str, Any] = {"lambda": lam}
    if method == "default":
        settings.update(grid=list(grid), n_starts=n_starts, max_nfev=max_iter or 100, regularize=regularize)
        x0 = None if prior is None else soil_vector(prior, b)
        fit = fit_default(data, lo, hi, lam, x0, tuple(int(g) for g in grid), n_starts, max_iter or 100,
                          regularize=regularize)
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
            pf = fit_single_stage(data, bnds, prior, maxiter)
        else:
            settings["sigma"] = sigma
            pf = fit_multi_stage(data, bnds, prior, sigma, cycle.normal, maxiter)
        theta = pf.theta
        x = soil_vector(theta, b)
        nfev = sum(s.nfev for s in pf.stages)
        success = all(s.success for s in pf.stages)
        failed = [s for s in pf.stages if not s.success]
        status = failed[0].status if failed else 0
        message = "; ".join(f"{s.name}: {s.message}" for s in pf.stages)
        if failed:
            message = "did not converge: " + message
        settings.update(maxiter=maxiter, initial_guess="given" if prior is not None else "mid-range of bounds")
        for s in pf.stages:
            stages.append(_paper_stage(s, data, b))
    time_s = time.perf_counter() - t0

    # Soil parameters: the paper's methods estimate k_c, k_phi directly; the default splits K.
    if method == "default":
        soil = soil_from_vector(x, b, bnds, prior)
    else:
        soil = SoilParams.from_array(np.clip(pf.theta, [bnds[k][0] for k in PARAMETER_NAMES],
                                             [bnds[k][1] for k in PARAMETER_NAMES]))
    forces = soil_forces(soil, state, bucket, options)
    in_soil = np.zeros(len(cycle), dtype=bool)
    in_soil[data.index] = True
    quality = FitQuality.from_forces(data.y_t, data.y_n, forces.tangential[data.index], forces.normal[data.index])
    f_t, f_n, jt, jn = data.forces_and_jacobian(x)
    wt, wn = math.sqrt(lam), math.sqrt(1.0 - lam)
    resid = np.concatenate([wt * (f_t - data.y_t), wn * (f_n - data.y_n)])
    jac = np.vstack([wt * jt, wn * jn])
    unc = analyse(jac, resid, x, lo, hi, float(np.mean(np.hypot(data.y_t, data.y_n))))
    cost = float(0.5 * np.sum((f_t - data.y_t) ** 2) + 0.5 * np.sum((f_n - data.y_n) ** 2))
    tension = int(np.count_nonzero(forces.flags[data.index] & FLAG_TENSION))
    warnings = assess(success=bool(success), obs_t=data.y_t, obs_n=data.y_n, pred_t=forces.tangential[data.index],
                      pred_n=forces.normal[data.index], percent_r=quality.percent_r, names=FIT_NAMES, values=x,
                      lower=lo, upper=hi)
    return Calibration(soil, method, float(x[5]), cost, bool(success), int(status), message, int(nfev), int(njev),
                       time_s, quality, stages, unc, prior, bnds, forces.tangential, forces.normal, in_soil,
                       tension, settings, warnings)


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
