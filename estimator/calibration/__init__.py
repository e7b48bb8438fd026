"""Calibration of the soil from one cycle, and prediction with the calibrated soil.

The shared model (soil, pile, paths, kinematics, force model, cycle log) lives
in :mod:`wheelloader.estimator`; this subpackage fits it:

* :mod:`.api`: :func:`calibrate` and its :class:`Calibration` result;
* :mod:`.fitmodel`: the force model arranged for fitting (linear basis, analytic Jacobian);
* :mod:`.varpro`: the ``"varpro"`` method (variable projection, global grid, analytic refinement);
* :mod:`.boxqp`: the exact batched box-constrained least-squares solver it uses;
* :mod:`.paper_methods`: the paper's ``"single-stage"`` and ``"multi-stage"`` baselines;
* :mod:`.uncertainty`: covariance and identifiability;
* :mod:`.prediction`: :func:`predict` forces along a new path.

Everything public is re-exported from :mod:`wheelloader.estimator`.
"""

from ..errors import CalibrationError
from .api import METHODS, Calibration, FitQuality, StageResult, calibrate, load_params
from .prediction import Prediction, predict
from .uncertainty import Uncertainty

__all__ = ["METHODS", "Calibration", "CalibrationError", "FitQuality", "Prediction", "StageResult", "Uncertainty",
           "calibrate", "load_params", "predict"]
