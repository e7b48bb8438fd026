"""Calibration of the soil from one cycle, and prediction with the calibrated soil.

The shared model (soil, pile, paths, kinematics, force model, cycle log) lives
in :mod:`wheelloader.estimator`; this subpackage fits it:

* :mod:`.api`: :func:`calibrate`, one fit function per method (:class:`~.api.MethodFit`);
* :mod:`.options`: :class:`CalibrationOptions`, the settings of a calibration, and the method names;
* :mod:`.result`: :class:`Calibration`, :class:`FitQuality`, :class:`StageResult`, and
  :class:`SolverResult`, the one result type of the internal solvers;
* :mod:`.verdict`: whether the data could determine the soil (:attr:`Calibration.trustworthy`);
* :mod:`.fitmodel`: the force model arranged for fitting (linear basis, analytic Jacobian);
* :mod:`.fit_factors`: the bearing factors at beta* and their derivatives, for fitting;
* :mod:`.varpro`: the ``"varpro"`` method (variable projection, global grid, analytic refinement);
* :mod:`.varpro_grid`: its global grid search (the projected cost and the refinement's starts);
* :mod:`.boxqp`: the exact batched box-constrained least-squares solver it uses;
* :mod:`.paper_methods`: the paper's ``"single-stage"`` and ``"multi-stage"`` baselines;
* :mod:`.uncertainty`: covariance and identifiability;
* :mod:`.prediction`: :func:`predict` forces along a new path.

Everything public is re-exported from :mod:`wheelloader.estimator`.
"""

from importlib import import_module
from typing import TYPE_CHECKING

from ..errors import CalibrationError

if TYPE_CHECKING:
    from .api import calibrate
    from .identify import HeldPrior
    from .options import DEFAULT_METHOD, METHOD_ALIASES, METHODS, CalibrationOptions, canonical_method
    from .prediction import Prediction, predict
    from .result import Calibration, FitQuality, SolverResult, StageResult, load_params
    from .uncertainty import Uncertainty
    from .verdict import FitWarning

#: Where each public name lives; a submodule is imported on first access (PEP 562), so reading a
#: params.json (:func:`load_params`) does not import the fitting methods and SciPy's filters.
_HOMES = {
    "calibrate": ".api",
    **dict.fromkeys(("DEFAULT_METHOD", "METHOD_ALIASES", "METHODS", "CalibrationOptions", "canonical_method"),
                    ".options"),
    **dict.fromkeys(("Prediction", "predict"), ".prediction"),
    **dict.fromkeys(("Calibration", "FitQuality", "SolverResult", "StageResult", "load_params"), ".result"),
    "Uncertainty": ".uncertainty",
    "HeldPrior": ".identify",
    "FitWarning": ".verdict",
}


def __getattr__(name: str):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(home, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_HOMES))


__all__ = ["DEFAULT_METHOD", "METHODS", "METHOD_ALIASES", "Calibration", "CalibrationError", "CalibrationOptions",
           "FitQuality", "FitWarning", "HeldPrior",
           "Prediction", "SolverResult", "StageResult", "Uncertainty", "calibrate", "canonical_method",
           "load_params", "predict"]
