"""Result types of the calibration: :class:`Calibration` (public), its :class:`FitQuality` and
:class:`StageResult`, and :class:`SolverResult`, the one result type of the internal solvers in SciPy's
:class:`~scipy.optimize.OptimizeResult` style; plus :func:`load_params`.

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
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import OptimizeResult

from ..errors import ParameterError
from ..jsonable import to_jsonable
from ..soil import SoilParams, as_soil
from ..soil_vector import SOIL_VECTOR_NAMES as FIT_NAMES
from .uncertainty import Uncertainty
from .verdict import FitWarning


class SolverResult(OptimizeResult):
    """Outcome of one internal solver run: a ``dict`` with attribute access, like SciPy's results.

    Every solver sets the common keys below; solver-specific keys are documented with the solver
    (:func:`~wheelloader.estimator.calibration.varpro.refine`,
    :func:`~wheelloader.estimator.calibration.varpro.fit_varpro`, the paper methods of
    :mod:`~wheelloader.estimator.calibration.paper_methods`).

    Attributes
    ----------
    x : numpy.ndarray
        Solution.
    cost : float
        Objective at ``x`` (each solver says which).
    success : bool
        Whether the solver reports convergence.
    status : int
        Solver status code (SciPy's).
    message : str
        Solver message.
    nfev, njev, nit : int
        Model evaluations, Jacobian evaluations, iterations.
    time_s : float
        Wall time [s].
    """

    def __init__(self, x: Any, cost: float, success: bool, status: int, message: str, nfev: int, njev: int = 0,
                 nit: int = 0, time_s: float = 0.0, **extra: Any) -> None:
        super().__init__(x=np.asarray(x, dtype=float), cost=float(cost), success=bool(success), status=int(status),
                         message=str(message), nfev=int(nfev), njev=int(njev), nit=int(nit), time_s=float(time_s),
                         **extra)


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
        ``"varpro"``, ``"single-stage"`` or ``"multi-stage"``.
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
    def model_options(self):
        """The :class:`~wheelloader.estimator.ModelOptions` this calibration fitted (the defaults unless set)."""
        from ..validity import DEFAULT_OPTIONS, ModelOptions

        stored = self.settings.get("model_options")
        return DEFAULT_OPTIONS if stored is None else ModelOptions(**stored)

    @property
    def fill_source(self) -> str:
        """``"log"`` or ``"model"``: where the calibration took the bucket load from (:func:`calibrate`'s ``fill``)."""
        return str(self.settings.get("fill", "log"))

    @property
    def force_model(self) -> str:
        """The force model fitted (:data:`~wheelloader.estimator.force_models.FORCE_MODELS`; ``"fee"`` unless set)."""
        return str(self.settings.get("force_model", "fee"))

    @property
    def payload(self):
        """The :class:`~wheelloader.estimator.payload.PayloadOptions` of a ``"fee-payload"`` calibration, else None."""
        from ..payload import PayloadOptions

        stored = self.settings.get("payload")
        return None if stored is None else PayloadOptions(**stored)

    @property
    def band_model(self):
        """What :func:`predict` needs for a prediction band (:class:`~.bands.BandModel`): covariance,
        residual autocorrelation time and residual noise model of this calibration."""
        from .bands import BandModel

        return BandModel.from_dict(self.settings["band_model"])

    @property
    def cycle_count(self) -> int:
        """Number of cycles this calibration fitted (1 unless a list of logs was given)."""
        return int(self.settings.get("cycles", {}).get("count", 1))

    @property
    def identifiability_by_cycles(self) -> list[dict[str, Any]]:
        """What the first 1, 2, ... cycles determined (several cycles only; else an empty list).

        One entry per prefix: ``{"cycles": j, "std_errors": {...}, "relative_std_errors": {...},
        "status": {...}, "weak_combinations": [...]}``, from the rows of those cycles in the
        weighted Jacobian at the final solution.
        """
        return list(self.settings.get("cycles", {}).get("identifiability", []))

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
        path.write_text(json.dumps(to_jsonable(self.to_dict()), indent=1, allow_nan=False))
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
            label = s.name if s.name.startswith("stage") else f"stage {s.name}"
            lines.append(f"  {label}: {s.time_s * 1e3:.1f} ms, {s.nfev} evals, "
                         + ", ".join(f"{k} {v[0]:.1f} N ({v[1]:.2f} %)" for k, v in s.rmse.items()))
        cycles = self.settings.get("cycles")
        if cycles:
            lines.append(f"  {cycles['count']} cycles fitted together:")
            for k, c in enumerate(cycles["per_cycle"]):
                lines.append(f"    cycle {k} ({c['name']}): {c['samples']} in-soil samples, weight {c['weight']:.3g}, "
                             f"F_R {c['rmse']['F_R'][1]:.2f} %")
        lines.append("identifiability:")
        lines.append(self.uncertainty.describe())
        if cycles:
            lines.append("  what each added cycle determined (relative std. error at the effective noise; "
                         "'bound' = at a bound):")
            names = list(FIT_NAMES)
            lines.append("    cycles " + " ".join(f"{n:>9}" for n in names))
            for entry in cycles["identifiability"]:
                cells = []
                for n in names:
                    rel = entry["relative_std_errors"][n]
                    cells.append(f"{'bound':>9}" if entry["status"][n] == "at bound"
                                 else f"{'inf':>9}" if rel is None else f"{rel:9.3g}")
                lines.append(f"    {entry['cycles']:>6} " + " ".join(cells))
        if self.tension_samples:
            lines.append(f"  note: the FEE force is clamped at 0 on {self.tension_samples} samples")
        return "\n".join(lines)


@dataclass(frozen=True)
class SavedModel:
    """What a params.json says beyond the soil: the calibration's model options, fill source, band model, force
    model and payload.

    Attributes are None when the file does not hold them (a bare 8-parameter JSON, a preset, an older file; its
    force model is then the paper's, ``"fee"``).
    """

    options: Any = None
    fill: str | None = None
    band_model: Any = None
    force_model: str | None = None
    payload: Any = None


def load_saved_model(path: str | Path) -> SavedModel:
    """Read :class:`SavedModel` from a params.json of ``wheelloader calibrate`` (:meth:`Calibration.save_json`)."""
    from ..validity import ModelOptions
    from .bands import BandModel

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError, RecursionError):
        return SavedModel()
    settings = (data.get("calibration") or {}).get("settings") or {} if isinstance(data, dict) else {}
    from ..force_models import check_force_model
    from ..payload import as_payload

    options = settings.get("model_options")
    band = settings.get("band_model")
    try:
        name = settings.get("force_model")
        payload = None if name is None else check_force_model(name, as_payload(settings.get("payload")))
        return SavedModel(None if options is None else ModelOptions(**options), settings.get("fill"),
                          None if band is None else BandModel.from_dict(band), name, payload)
    except (TypeError, ParameterError) as exc:
        raise ParameterError(f"{path}: calibration settings: {exc}") from None


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
    if not isinstance(source, (str, os.PathLike)):
        raise ParameterError("soil parameters must be a params.json path, a preset name, a dict, a Calibration or "
                             f"SoilParams, got {type(source).__name__}")
    path = Path(source)
    if path.suffix.lower() == ".json" or path.exists():
        if not path.exists():
            raise FileNotFoundError(2, "No such file", str(path))
        try:
            data = json.loads(path.read_text(encoding="utf-8-sig"))
        except (json.JSONDecodeError, UnicodeDecodeError, IsADirectoryError) as exc:
            raise ParameterError(f"{path}: not a valid JSON file ({exc})") from None
        except RecursionError:
            raise ParameterError(f"{path}: not a valid JSON file (nested too deeply to read)") from None
        if not isinstance(data, dict):
            raise ParameterError(f"{path}: expected a JSON object with the soil parameters")
        try:
            return load_params(data)
        except ParameterError as exc:
            raise ParameterError(f"{path}: {exc}") from None
    return as_soil(str(source))
