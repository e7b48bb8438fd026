"""Prediction bands: how far the forces of a new path may lie from the calibrated model's prediction.

Two sources of spread, added as variances per sample (Gaussian, independent):

* **Parameters.** The calibration's covariance ``C`` of the fit vector
  (:class:`~wheelloader.estimator.calibration.uncertainty.Uncertainty`: ``s^2 (J^T J)^-1``),
  inflated by the integrated autocorrelation time ``tau`` of the training residuals
  (:func:`~wheelloader.estimator.calibration.uncertainty.integrated_autocorrelation_time`): correlated
  misfit carries ``M / tau`` independent samples, not ``M``. Propagated to each sample of the new path
  through the model's analytic Jacobian, ``var_p = j^T (tau C) j``. Parameters on a bound have no
  covariance and count as known.
* **Residual noise model.** What the model cannot fit at any parameters: the training residuals of F_R
  are fitted as ``var_r = sigma_0^2 + (c F_R,pred)^2`` (a floor plus a part proportional to the
  predicted force; non-negative least squares on the squared residuals), :func:`residual_noise_model`.

The band of level ``p`` is ``mean +- k z_p sqrt(var_p + var_r)`` with ``z_p`` the two-sided normal
quantile and ``k`` the band's scale (``CalibrationOptions(band_scale=)``, default 1; > 1 where validation
paths showed that a new path is predicted worse than the training residuals say). Both parts are
estimated on the training cycle(s); a new path the model describes worse than its training cycles gets
a band that is too narrow at ``k = 1``, which the coverage tables of ``benchmarks/paper_experiments.py``
and ``benchmarks/transfer.py`` measure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import check_range
from ..errors import ParameterError
from ..kinematics import ContactState
from ..machine import Bucket
from ..soil import SoilParams
from ..soil_vector import soil_vector
from ..validity import ModelOptions
from .fitmodel import FitData

#: Default level of a prediction band.
DEFAULT_LEVEL = 0.9


def residual_noise_model(observed_r: np.ndarray, predicted_r: np.ndarray) -> tuple[float, float]:
    """``(sigma_0, c)`` of ``var = sigma_0^2 + (c F_pred)^2`` fitted to the squared F_R residuals (NNLS)."""
    from scipy.optimize import nnls

    obs, pred = np.asarray(observed_r, float), np.asarray(predicted_r, float)
    r2 = (obs - pred) ** 2
    if r2.size == 0 or not np.any(r2 > 0.0):
        return 0.0, 0.0
    a = np.column_stack([np.ones_like(pred), pred**2])
    coef, _ = nnls(a, r2)
    return float(math.sqrt(coef[0])), float(math.sqrt(coef[1]))


@dataclass(frozen=True)
class BandModel:
    """What a prediction band needs from a calibration (JSON round trip via :meth:`to_dict`).

    Attributes
    ----------
    covariance : numpy.ndarray
        7 x 7 covariance of the fit vector (NaN rows for parameters on a bound).
    tau : float
        Integrated autocorrelation time of the training residuals [samples] (>= 1).
    sigma_0, relative : float
        Residual noise model ``var = sigma_0^2 + (relative F_R,pred)^2`` [N, -].
    scale : float
        Factor on the band's standard deviation (default 1).
    """

    covariance: np.ndarray
    tau: float
    sigma_0: float
    relative: float
    scale: float = 1.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping (NaN as None)."""
        cov = [[None if not np.isfinite(v) else float(v) for v in row] for row in self.covariance]
        out = {"covariance": cov, "tau": self.tau, "sigma_0_N": self.sigma_0, "relative": self.relative}
        if self.scale != 1.0:
            out["scale"] = self.scale
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BandModel:
        """Inverse of :meth:`to_dict`."""
        try:
            cov = np.array([[np.nan if v is None else float(v) for v in row] for row in data["covariance"]])
            if cov.shape != (7, 7):
                raise ValueError(f"covariance has shape {cov.shape}, expected (7, 7)")
            return cls(cov, float(data["tau"]), float(data["sigma_0_N"]), float(data["relative"]),
                       float(data.get("scale", 1.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise ParameterError(f"band model: {exc}") from None


@dataclass(frozen=True, eq=False)
class PredictionBand:
    """A prediction band of F_T, F_N and F_R along a path.

    Attributes
    ----------
    level : float
        Two-sided coverage the band aims at (e.g. 0.9).
    std_t, std_n, std_r : numpy.ndarray
        Standard deviation of F_T, F_N, F_R per sample [N] (parameters and residual noise).
    parameter_std_r : numpy.ndarray
        The parameters' share of ``std_r`` [N].
    lower_r, upper_r : numpy.ndarray
        Band of F_R [N] (lower clipped at 0).
    """

    level: float
    std_t: np.ndarray
    std_n: np.ndarray
    std_r: np.ndarray
    parameter_std_r: np.ndarray
    lower_r: np.ndarray
    upper_r: np.ndarray

    def coverage(self, observed_r: np.ndarray, mask: np.ndarray | None = None) -> float:
        """Share of ``observed_r`` inside the band (over ``mask``, default every sample)."""
        obs = np.asarray(observed_r, float)
        inside = (obs >= self.lower_r) & (obs <= self.upper_r)
        if mask is not None:
            inside = inside[mask]
        return float(np.mean(inside)) if inside.size else float("nan")


def normal_quantile(level: float) -> float:
    """Two-sided standard-normal quantile ``z`` with ``P(|Z| <= z) = level``."""
    from statistics import NormalDist

    check_range("band level", level, 0.0, 1.0, low_open=True, high_open=True)
    return float(NormalDist().inv_cdf(0.5 + 0.5 * level))


def prediction_band(model: BandModel, soil: SoilParams, state: ContactState, bucket: Bucket, options: ModelOptions,
                    tangential: np.ndarray, normal: np.ndarray, level: float = DEFAULT_LEVEL) -> PredictionBand:
    """Band of the predicted forces ``tangential``, ``normal`` (module docstring).

    Parameters
    ----------
    model : BandModel
        From the calibration (:attr:`Calibration.band_model`).
    soil : SoilParams
        The calibrated soil (its fit vector is where the Jacobian is taken).
    state, bucket, options
        The prediction's contact state, bucket and force-model options.
    tangential, normal : numpy.ndarray
        The predicted F_T, F_N along the path [N].
    level : float
        Two-sided level of the band.
    """
    z = normal_quantile(level)
    n = len(state)
    f_t, f_n = np.asarray(tangential, float), np.asarray(normal, float)
    f_r = np.hypot(f_t, f_n)
    var_t, var_n, var_r = np.zeros(n), np.zeros(n), np.zeros(n)
    idx = np.flatnonzero(state.depth > 0.0)
    cov = np.where(np.isfinite(model.covariance), model.covariance, 0.0) * max(model.tau, 1.0)
    if idx.size:
        data = FitData.from_state(state, np.zeros(n), np.zeros(n), bucket, options, min_samples=1)
        _, _, jt, jn = data.forces_and_jacobian(soil_vector(soil, bucket.edge_thickness))
        var_t[idx] = np.einsum("ij,jk,ik->i", jt, cov, jt)
        var_n[idx] = np.einsum("ij,jk,ik->i", jn, cov, jn)
        fr = np.maximum(f_r[idx], 1e-9)
        jr = (f_t[idx, None] * jt + f_n[idx, None] * jn) / fr[:, None]
        var_r[idx] = np.einsum("ij,jk,ik->i", jr, cov, jr)
    k = model.scale
    param_std = k * np.sqrt(np.maximum(var_r, 0.0))
    noise = lambda f: model.sigma_0**2 + (model.relative * f) ** 2  # noqa: E731
    std_t = k * np.sqrt(np.maximum(var_t, 0.0) + noise(np.abs(f_t)))
    std_n = k * np.sqrt(np.maximum(var_n, 0.0) + noise(np.abs(f_n)))
    std_r = k * np.sqrt(np.maximum(var_r, 0.0) + noise(f_r))
    return PredictionBand(float(level), std_t, std_n, std_r, param_std, np.maximum(f_r - z * std_r, 0.0),
                          f_r + z * std_r)
