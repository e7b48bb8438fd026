"""A learned correction beyond the FEE: a ridge residual on dimensionless inputs (NumPy only).

The force model ``"fee-payload"`` leaves a floor of 12-15 % F_R RMSE on the project's continuum cycles
(``docs/results/transfer.md``) whatever its parameters. This module learns what it misses, as a function of the
blade's state alone, so that one cycle still fits the handful of physical soil parameters:

    F_T = F_T,model(theta) + s r_T(x),   F_N = F_N,model(theta) + s r_N(x),   s = rho_ref g w L^2,

with ``x`` the dimensionless inputs of :func:`features` (depth over the bucket's floor length, the surcharge's
contact ramp, the blade angle to the surface rho, the slope alpha, the blade angle, the carved and the kept fill
as fractions of the capacity, and the speed as a Froude number ``|v| / sqrt(g L)``), ``r`` a quadratic
polynomial in them, and ``s`` a fixed force scale (``rho_ref`` = :data:`REFERENCE_DENSITY`). Because ``r`` does
not depend on ``theta``, the soil is fitted jointly with it exactly: calibrate ``theta`` on the measured forces
minus ``s r(x)`` (:func:`corrected_log`) and add ``s r(x)`` to the prediction (:func:`residual_forces`).

The weights come from :func:`fit_residual` over training cycles (each with its own calibration); a
:class:`ResidualModel` is plain JSON (:meth:`ResidualModel.to_dict`). Outside the training ranges of the inputs
(:attr:`ResidualModel.low`, :attr:`ResidualModel.high`) it is not to be trusted: :meth:`ResidualModel.outside`
flags those samples.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from .cyclelog import CycleLog
from .errors import ParameterError
from .force_model import GRAVITY
from .kinematics import ContactState

__all__ = ["FEATURE_NAMES", "REFERENCE_DENSITY", "ResidualModel", "corrected_log", "features", "fit_residual",
           "force_scale", "residual_forces"]

#: Density of the fixed force scale ``s = rho_ref g w L^2`` [kg/m^3].
REFERENCE_DENSITY = 1500.0
FEATURE_NAMES = ("depth_over_length", "contact_ramp", "rho", "alpha", "blade_angle", "carved_fill_fraction",
                 "kept_fill_fraction", "froude")


def features(state: ContactState, log: CycleLog, contact_depth: float = 0.02) -> np.ndarray:
    """The dimensionless inputs (samples x :data:`FEATURE_NAMES`) of a log's contact state."""
    bucket = log.bucket
    length = bucket.floor_length
    depth = np.maximum(state.depth, 0.0)
    kept = state.fill_volume if state.carried_volume is None else state.carried_volume
    vx, vz, _ = log.path.velocity()
    return np.column_stack([depth / length, np.minimum(depth / contact_depth, 1.0), state.rho, state.alpha,
                            state.blade_angle, state.fill_volume / bucket.capacity, kept / bucket.capacity,
                            np.hypot(vx, vz) / np.sqrt(GRAVITY * length)])


def force_scale(log: CycleLog) -> float:
    """``s = rho_ref g w L^2`` [N] for the log's bucket."""
    return REFERENCE_DENSITY * GRAVITY * log.bucket.width * log.bucket.floor_length ** 2


def _design(x: np.ndarray) -> np.ndarray:
    """``[1, x_i, x_i x_j (i <= j)]``."""
    n, m = x.shape
    cols = [np.ones(n)] + [x[:, i] for i in range(m)]
    cols += [x[:, i] * x[:, j] for i in range(m) for j in range(i, m)]
    return np.column_stack(cols)


@dataclass(frozen=True)
class ResidualModel:
    """Ridge weights of the residual (module docstring).

    Attributes
    ----------
    weights : numpy.ndarray
        (design columns x 2): F_T and F_N residuals over the force scale.
    mean, std : numpy.ndarray
        Standardisation of the inputs (per feature).
    low, high : numpy.ndarray
        The inputs' 1st and 99th percentiles over the training samples (the trusted range).
    """

    weights: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    low: np.ndarray
    high: np.ndarray

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Dimensionless residuals (samples x 2) at inputs ``x``, each clipped to the trusted range first
        (a quadratic must not extrapolate)."""
        return _design((np.clip(x, self.low, self.high) - self.mean) / self.std) @ self.weights

    def outside(self, x: np.ndarray) -> np.ndarray:
        """True where a sample's inputs leave the training range."""
        return np.any((x < self.low) | (x > self.high), axis=1)

    def to_dict(self) -> dict:
        """Plain-JSON form."""
        return {"features": list(FEATURE_NAMES), "reference_density": REFERENCE_DENSITY,
                **{k: getattr(self, k).tolist() for k in ("weights", "mean", "std", "low", "high")}}

    @classmethod
    def from_dict(cls, data: dict) -> ResidualModel:
        """Inverse of :meth:`to_dict`."""
        if list(data.get("features", [])) != list(FEATURE_NAMES):
            raise ParameterError(f"residual model: features must be {list(FEATURE_NAMES)}")
        return cls(*(np.asarray(data[k], dtype=float) for k in ("weights", "mean", "std", "low", "high")))


def fit_residual(samples: Sequence[tuple[np.ndarray, np.ndarray]], ridge: float = 1e-3) -> ResidualModel:
    """Ridge fit of the residuals: ``samples`` are ``(x, r)`` pairs per cycle, ``r`` (samples x 2) dimensionless.

    ``ridge`` is the penalty relative to the mean diagonal of the normal matrix.
    """
    x = np.concatenate([s[0] for s in samples])
    r = np.concatenate([s[1] for s in samples])
    mean, std = x.mean(axis=0), x.std(axis=0)
    std = np.where(std > 0.0, std, 1.0)
    a = _design((x - mean) / std)
    gram = a.T @ a
    lam = ridge * float(np.trace(gram)) / gram.shape[0]
    weights = np.linalg.solve(gram + lam * np.eye(gram.shape[0]), a.T @ r)
    return ResidualModel(weights, mean, std, np.percentile(x, 1, axis=0), np.percentile(x, 99, axis=0))


def residual_forces(model: ResidualModel, state: ContactState, log: CycleLog,
                    contact_depth: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """``(s r_T, s r_N)`` [N] along the log."""
    r = model.predict(features(state, log, contact_depth)) * force_scale(log)
    return r[:, 0], r[:, 1]


def corrected_log(model: ResidualModel, state: ContactState, log: CycleLog,
                  contact_depth: float = 0.02) -> CycleLog:
    """The log with the learned residual taken off its forces (what the soil parameters are fitted to)."""
    r_t, r_n = residual_forces(model, state, log, contact_depth)
    return replace(log, tangential=log.tangential - r_t, normal=log.normal - r_n)
