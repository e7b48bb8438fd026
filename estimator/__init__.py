"""Soil model and calibration: the modified Fundamental Earthmoving Equation.

Everything the estimator, the environments and the planner share lives here:
soil parameters, bucket and loader, pile geometry, bucket paths, contact
kinematics, the validity domain and failure angle, the force model and cycle
logs. Calibration and prediction are the subpackage
:mod:`wheelloader.estimator.calibration`, re-exported here and imported on
first use (it needs SciPy's optimisers, which the envs and the planner do not).
"""

from typing import TYPE_CHECKING

from .cyclelog import CycleLog, load_path_csv, save_path_csv
from .errors import CalibrationError, CycleLogError, ParameterError, PlanningError, WheelloaderError
from .force_model import (
    DEFAULT_OPTIONS,
    FLAG_NAMES,
    GRAVITY,
    ModelOptions,
    SoilForces,
    bearing_factors,
    optimal_beta,
    soil_forces,
    soil_forces_single,
)
from .force_models import DEFAULT_PAYLOAD, DEFAULT_WEDGE_OFFSET, FORCE_MODELS
from .kinematics import DEFAULT_SLOPE_WINDOW, ContactState, blade_length_in_soil, contact_single, contact_state
from .machine import Bucket, Loader
from .paths import BucketPath, bezier_path, default_path, paper_paths, polyline_path
from .payload import PayloadOptions, fit_payload
from .pile import CarveResult, Pile, SurfaceCarver
from .soil import PAPER_BOUNDS, PARAMETER_NAMES, PRESET_NAMES, SoilParams, as_soil, preset
from .soil_vector import SOIL_VECTOR_NAMES, soil_from_vector, soil_vector
from .synthetic import random_bezier_path, random_soil, synthetic_cycle
from .validity import FLAG_OUT_OF_SOIL

if TYPE_CHECKING:
    from .calibration import (
        DEFAULT_METHOD,
        METHOD_ALIASES,
        METHODS,
        Calibration,
        CalibrationOptions,
        FitQuality,
        FitWarning,
        Prediction,
        StageResult,
        Uncertainty,
        calibrate,
        canonical_method,
        load_params,
        predict,
    )

#: Names re-exported from :mod:`.calibration`, imported on first access (PEP 562).
_CALIBRATION_NAMES = frozenset({
    "DEFAULT_METHOD", "METHOD_ALIASES", "METHODS", "Calibration", "CalibrationOptions", "FitQuality", "FitWarning",
    "Prediction", "StageResult", "Uncertainty", "calibrate", "canonical_method", "load_params", "predict",
})


def __getattr__(name: str):
    if name in _CALIBRATION_NAMES:
        from . import calibration

        value = getattr(calibration, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _CALIBRATION_NAMES)


__all__ = [
    "Bucket", "BucketPath", "Calibration", "CalibrationError", "CalibrationOptions", "CarveResult", "ContactState",
    "CycleLog", "CycleLogError", "DEFAULT_METHOD", "DEFAULT_OPTIONS", "DEFAULT_PAYLOAD", "DEFAULT_WEDGE_OFFSET",
    "FORCE_MODELS", "DEFAULT_SLOPE_WINDOW", "FLAG_NAMES", "FLAG_OUT_OF_SOIL", "FitQuality", "FitWarning", "GRAVITY",
    "Loader",
    "METHODS", "METHOD_ALIASES", "ModelOptions", "PAPER_BOUNDS", "PARAMETER_NAMES", "PRESET_NAMES", "ParameterError",
    "PayloadOptions", "Pile", "PlanningError", "Prediction", "SOIL_VECTOR_NAMES", "SoilForces", "SoilParams",
    "StageResult", "SurfaceCarver", "Uncertainty", "WheelloaderError", "as_soil", "bearing_factors", "bezier_path",
    "blade_length_in_soil", "calibrate", "canonical_method", "contact_single", "contact_state", "default_path",
    "fit_payload", "load_params", "load_path_csv", "optimal_beta", "paper_paths", "polyline_path", "predict",
    "preset", "random_bezier_path", "random_soil", "save_path_csv", "soil_forces", "soil_forces_single",
    "soil_from_vector", "soil_vector", "synthetic_cycle"
]
