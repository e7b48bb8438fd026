"""Soil model and calibration: the modified Fundamental Earthmoving Equation.

Everything the estimator, the environments and the planner share lives here:
soil parameters, bucket and loader, pile geometry, bucket paths, contact
kinematics, the validity domain and failure angle, the force model and cycle
logs. Calibration and prediction are the subpackage
:mod:`wheelloader.estimator.calibration`, re-exported here.
"""

from .calibration import (
    METHODS,
    Calibration,
    FitQuality,
    FitWarning,
    Prediction,
    StageResult,
    Uncertainty,
    calibrate,
    load_params,
    predict,
)
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
from .kinematics import ContactState, contact_single, contact_state
from .machine import Bucket, Loader
from .paths import BucketPath, bezier_path, default_path, paper_paths, polyline_path
from .pile import CarveResult, Pile, SurfaceCarver
from .soil import PAPER_BOUNDS, PARAMETER_NAMES, PRESET_NAMES, SoilParams, as_soil, preset
from .soil_vector import SOIL_VECTOR_NAMES, soil_from_vector, soil_vector
from .synthetic import random_bezier_path, random_soil, synthetic_cycle

__all__ = [
    "CycleLog", "load_path_csv", "save_path_csv",
    "METHODS", "Calibration", "FitQuality", "FitWarning", "Prediction", "StageResult", "Uncertainty", "calibrate",
    "load_params", "predict", "random_bezier_path", "random_soil", "synthetic_cycle",
    "Bucket", "BucketPath", "CalibrationError", "CarveResult", "ContactState", "CycleLogError",
    "DEFAULT_OPTIONS", "FLAG_NAMES", "GRAVITY", "Loader", "ModelOptions", "PAPER_BOUNDS", "PARAMETER_NAMES",
    "PRESET_NAMES", "ParameterError", "Pile", "PlanningError", "SOIL_VECTOR_NAMES", "SoilForces", "SoilParams",
    "SurfaceCarver", "soil_from_vector", "soil_vector",
    "WheelloaderError", "as_soil", "bearing_factors", "bezier_path", "contact_single", "contact_state",
    "default_path", "optimal_beta", "paper_paths", "polyline_path", "preset", "soil_forces",
    "soil_forces_single",
]
