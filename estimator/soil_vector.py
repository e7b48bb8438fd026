"""The soil vector: the seven soil quantities the forces determine, one order and one set of names.

The forces depend on ``k_c`` and ``k_phi`` only through ``K = k_c / b + k_phi`` (eq 15, ``b`` the
cutting-edge thickness), so the calibration fits, and the planner's CasADi model takes, the vector

    (gamma, cohesion, adhesion, phi, delta, K, n)        names :data:`SOIL_VECTOR_NAMES`

This module is the one converter between it and :class:`~wheelloader.estimator.soil.SoilParams` (or
the paper's eight-parameter array, eq 18), both ways, and of the bounds.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .checks import check_range
from .errors import ParameterError
from .soil import PAPER_BOUNDS, PARAMETER_NAMES, SoilParams

#: Names of the soil vector (K = k_c / b + k_phi, eq 15).
SOIL_VECTOR_NAMES: tuple[str, ...] = ("gamma", "cohesion", "adhesion", "phi", "delta", "K", "n")
#: Indices of the entries the forces are linear in (for fixed phi, delta, n).
LINEAR_INDEX = (0, 1, 2, 5)
#: Indices of the entries the forces depend on nonlinearly.
NONLINEAR_INDEX = (3, 4, 6)


def soil_vector(soil: SoilParams | Any, edge_thickness: float) -> np.ndarray:
    """The soil vector of a :class:`SoilParams` or of eight parameters in :data:`PARAMETER_NAMES` order.

    Parameters
    ----------
    soil : SoilParams or array_like
        The soil; an array of eight values (the paper's methods' parameter vector, eq 18) is not
        validated, so that optimisers may probe any point.
    edge_thickness : float
        Cutting-edge thickness b [m].
    """
    check_range("edge_thickness", edge_thickness, 0.0, None, low_open=True)  # m
    theta = soil.to_array() if isinstance(soil, SoilParams) else np.asarray(soil, dtype=float).ravel()
    if theta.size != len(PARAMETER_NAMES):
        raise ParameterError(f"expected {len(PARAMETER_NAMES)} soil parameters, got {theta.size}")
    return np.array([theta[0], theta[1], theta[2], theta[3], theta[4], theta[5] / edge_thickness + theta[6],
                     theta[7]])


def vector_bounds(bounds: dict[str, tuple[float, float]], edge_thickness: float) -> tuple[np.ndarray, np.ndarray]:
    """``(lower, upper)`` of the soil vector from bounds on the eight parameters (K from k_c, k_phi)."""
    lower = soil_vector(np.array([bounds[name][0] for name in PARAMETER_NAMES]), edge_thickness)
    upper = soil_vector(np.array([bounds[name][1] for name in PARAMETER_NAMES]), edge_thickness)
    return lower, upper


def split_sinkage(K: float, edge_thickness: float, bounds: dict[str, tuple[float, float]] = PAPER_BOUNDS,
                  prior: SoilParams | None = None) -> tuple[float, float]:
    """Split the identifiable ``K = k_c / b + k_phi`` into ``(k_c, k_phi)``.

    Forces determine only K (eq 15). The split is a convention, not an
    estimate: with a ``prior`` whose K is positive, keep its share of
    ``k_c / b`` in K; otherwise put everything into ``k_phi``. The result is
    then moved inside the bounds keeping K exact whenever the bounds allow.
    """
    b = edge_thickness
    kc_lo, kc_hi = bounds["k_c"]
    kp_lo, kp_hi = bounds["k_phi"]
    share = 0.0
    if prior is not None and prior.sinkage_modulus(b) > 0.0:
        share = (prior.k_c / b) / prior.sinkage_modulus(b)
    kc = share * K * b
    kc = min(max(kc, kc_lo), kc_hi)
    kp = K - kc / b
    if kp > kp_hi:  # move the excess back into k_c
        kp = kp_hi
        kc = min(max((K - kp) * b, kc_lo), kc_hi)
    elif kp < kp_lo:
        kp = kp_lo
        kc = min(max((K - kp) * b, kc_lo), kc_hi)
    return float(kc), float(kp)


def soil_from_vector(vector: Any, edge_thickness: float, bounds: dict[str, tuple[float, float]] = PAPER_BOUNDS,
                     prior: SoilParams | None = None) -> SoilParams:
    """:class:`SoilParams` from a soil vector, splitting K with :func:`split_sinkage`."""
    p = np.asarray(vector, dtype=float).ravel()
    if p.size != len(SOIL_VECTOR_NAMES):
        raise ParameterError(f"expected a soil vector of {len(SOIL_VECTOR_NAMES)} values, got {p.size}")
    kc, kp = split_sinkage(float(p[5]), edge_thickness, bounds, prior)
    return SoilParams(gamma=float(p[0]), cohesion=float(p[1]), adhesion=float(p[2]), phi=float(p[3]),
                      delta=float(p[4]), k_c=kc, k_phi=kp, n=float(p[6]))
