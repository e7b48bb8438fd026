"""The modified Fundamental Earthmoving Equation (paper Section II).

Forces on the bucket blade from the soil wedge (eq 1), with the bearing
capacity factors in the canonical sine-cosine form (eqs 10-13), the failure
angle beta chosen by minimising N_gamma under the continuity constraints of
eq 14, Bekker's penetration pressure (eq 15) and the blade-frame forces
F_T, F_N (eqs 16-17).

Validity domain (decided here, see README "Validity domain")
-----------------------------------------------------------
* ``rho`` is clamped to ``[rho_min, pi - eps1 - eps2 - delta - phi]``: below
  ``rho_min`` (10 deg, paper Section II-A) the blade is nearly parallel to
  the surface and the wedge vanishes; above the upper limit the feasible
  range of beta in eq 14 is empty. Flags :data:`FLAG_RHO_LOW` /
  :data:`FLAG_RHO_HIGH`.
* ``alpha`` is clamped to ``[-alpha_max, alpha_max]`` (60 deg);
  :data:`FLAG_ALPHA_CLAMPED`.
* beta is searched on the physically valid branch ``eps1 <= beta <=
  min(pi - (rho + delta + phi) - eps2, pi/2 - alpha)``, where every factor
  is >= 0 (N_gamma, N_c, N_q) and finite. On that branch N_gamma is
  unimodal (checked numerically over the whole parameter box), so the
  minimiser is the unique root of dlnN_gamma/dbeta, or a bound. At the
  bound ``beta = pi/2 - alpha`` N_gamma = 0.
* A negative FEE force (possible when adhesion dominates: N_a < 0 for
  rho + beta + phi < pi/2) would mean the soil pulls the blade; it is
  clamped to 0 (:data:`FLAG_TENSION`).
* Tip out of soil (depth <= 0): every term is zero (:data:`FLAG_OUT_OF_SOIL`).
  The surcharge term ``W_load N_q`` is ramped in linearly over the first
  ``contact_depth`` metres of depth so that the force stays continuous when
  the tip enters or leaves the soil with a loaded bucket (our addition; the
  paper does not say what happens at exit).

Every clamp is continuous, so forces are finite, non-negative and continuous
along smooth paths everywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError
from .kinematics import ContactState
from .machine import Bucket
from .soil import SoilParams

#: Standard gravity [m/s^2].
GRAVITY = 9.81

FLAG_OUT_OF_SOIL = 1
FLAG_RHO_LOW = 2
FLAG_RHO_HIGH = 4
FLAG_ALPHA_CLAMPED = 8
FLAG_TENSION = 16

#: Human-readable names of the flag bits.
FLAG_NAMES: dict[int, str] = {
    FLAG_OUT_OF_SOIL: "tip out of soil",
    FLAG_RHO_LOW: "rho below rho_min (blade too flat)",
    FLAG_RHO_HIGH: "rho + delta + phi too close to pi (no valid beta)",
    FLAG_ALPHA_CLAMPED: "slope angle clamped",
    FLAG_TENSION: "FEE force clamped at 0 (adhesion would pull)",
}


@dataclass(frozen=True)
class ModelOptions:
    """Numerical options of the force model.

    Parameters
    ----------
    eps1, eps2 : float
        Margins of eq 14 [rad]; default 5 deg each (paper).
    rho_min : float
        Smallest blade angle relative to the surface [rad]; default 10 deg (paper).
    alpha_max : float
        Largest |slope angle| used [rad]; default 60 deg.
    contact_depth : float
        Depth over which the surcharge ``W_load N_q`` ramps in [m]; default 0.02 m.
    """

    eps1: float = math.radians(5.0)
    eps2: float = math.radians(5.0)
    rho_min: float = math.radians(10.0)
    alpha_max: float = math.radians(60.0)
    contact_depth: float = 0.02

    def __post_init__(self) -> None:
        for name in ("eps1", "eps2", "rho_min", "alpha_max", "contact_depth"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ParameterError(f"ModelOptions.{name} must be a finite number > 0, got {value!r}")
        if self.eps1 + self.eps2 + self.rho_min >= math.pi / 2 or self.alpha_max >= math.pi / 2 - self.eps1:
            raise ParameterError("ModelOptions: eps1 + eps2 + rho_min must be < 90 deg and alpha_max < 90 deg - eps1")


DEFAULT_OPTIONS = ModelOptions()


# ---------------------------------------------------------------- factors
def bearing_factors(alpha, rho, beta, phi, delta):
    """Bearing capacity factors in the canonical sine-cosine form (eqs 10-13).

    All angles in radians; array inputs broadcast.

    Returns
    -------
    tuple of numpy.ndarray
        ``(N_gamma, N_c, N_a, N_q)``.
    """
    alpha, rho, beta = np.asarray(alpha, float), np.asarray(rho, float), np.asarray(beta, float)
    s_beta = np.sin(rho + delta + beta + phi)
    sin_beta = np.sin(beta)
    n_gamma = np.cos(alpha + beta) * np.sin(alpha + beta + phi) / (2.0 * np.cos(alpha) * sin_beta * s_beta)  # eq 10
    n_c = math.cos(phi) / (sin_beta * s_beta) if np.ndim(phi) == 0 else np.cos(phi) / (sin_beta * s_beta)  # eq 11
    n_a = -np.cos(rho + beta + phi) / (np.sin(rho) * s_beta)  # eq 12 (sin(beta+phi) cancelled)
    n_q = np.sin(alpha + beta + phi) / s_beta  # eq 13
    return n_gamma, n_c, n_a, n_q


def bearing_factors_cotangent(alpha, rho, beta, phi, delta):
    """Bearing capacity factors in the paper's original cotangent form (eqs 2-5), for checks."""
    cot = lambda v: 1.0 / np.tan(v)  # noqa: E731
    den = np.cos(rho + delta) + np.sin(rho + delta) * cot(beta + phi)
    n_gamma = (cot(beta) - np.tan(alpha)) * (np.cos(alpha) + np.sin(alpha) * cot(beta + phi)) / (2.0 * den)
    n_c = (1.0 + cot(beta) * cot(beta + phi)) / den
    n_a = (1.0 - cot(rho) * cot(beta + phi)) / den
    n_q = (np.cos(alpha) + np.sin(alpha) * cot(beta + phi)) / den
    return n_gamma, n_c, n_a, n_q


def clamp_angles(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS):
    """Clamp (alpha, rho) into the validity domain; return ``(alpha_eff, rho_eff, flags)``."""
    alpha = np.asarray(alpha, dtype=float)
    rho = np.asarray(rho, dtype=float)
    rho_hi = math.pi - options.eps1 - options.eps2 - delta - phi
    flags = np.where(rho < options.rho_min, FLAG_RHO_LOW, 0)
    flags |= np.where(rho > rho_hi, FLAG_RHO_HIGH, 0)
    flags |= np.where(np.abs(alpha) > options.alpha_max, FLAG_ALPHA_CLAMPED, 0)
    rho_eff = np.clip(rho, options.rho_min, rho_hi)
    alpha_eff = np.clip(alpha, -options.alpha_max, options.alpha_max)
    return alpha_eff, rho_eff, flags.astype(np.int64)


def beta_bounds(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS):
    """Feasible beta range ``(lo, hi)`` on the valid branch, for clamped angles."""
    hi = np.minimum(math.pi - (rho + delta + phi) - options.eps2, 0.5 * math.pi - alpha)
    lo = np.full_like(hi, options.eps1)
    return lo, hi


def log_ngamma_slope(beta, alpha, phi, s, tan=np.tan):
    """d ln N_gamma / d beta and its derivative (for Newton on eq 14), ``s = rho + delta + phi``.

    ``tan`` is the tangent of the array library (NumPy by default; the
    planner passes ``casadi.tan`` for its symbolic Newton steps).
    """
    t1 = tan(alpha + beta)
    c2 = 1.0 / tan(alpha + beta + phi)
    c3 = 1.0 / tan(beta)
    c4 = 1.0 / tan(beta + s)
    g = -t1 + c2 - c3 - c4
    dg = -t1 * t1 - c2 * c2 + c3 * c3 + c4 * c4
    return g, dg


def optimal_beta(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS,
                 tol: float = 1e-11, max_iter: int = 60, guess=None) -> np.ndarray:
    """Failure angle beta* minimising N_gamma (eq 10) under eq 14, on the valid branch.

    ``alpha`` and ``rho`` must already be clamped (see :func:`clamp_angles`).
    ``phi`` and ``delta`` may be scalars or arrays (one soil per sample, as in
    a batch of environments); all inputs broadcast. ``guess`` optionally
    warm-starts the iteration (e.g. the previous step's beta*). Safeguarded
    Newton on ``d ln N_gamma / d beta`` inside a bisection bracket.
    """
    alpha, rho, phi, delta = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (alpha, rho, phi, delta)))
    s = rho + delta + phi
    lo, hi = beta_bounds(alpha, rho, phi, delta, options)
    g_lo, _ = log_ngamma_slope(lo, alpha, phi, s)
    g_hi, _ = log_ngamma_slope(hi, alpha, phi, s)
    at_lo = g_lo >= 0.0
    at_hi = g_hi <= 0.0
    inner = ~(at_lo | at_hi)
    beta = np.array(np.where(at_lo, lo, hi), dtype=float)
    if np.any(inner):
        a, b, al, ph, ss = lo[inner], hi[inner], alpha[inner], phi[inner], s[inner]
        x = 0.5 * (a + b)
        if guess is not None:
            g0 = np.broadcast_to(np.asarray(guess, dtype=float), alpha.shape)[inner]
            x = np.where((g0 > a) & (g0 < b), g0, x)
        # iterate only on the samples that have not converged yet (a batch is as slow as its slowest sample)
        out = np.empty_like(x)
        active = np.arange(x.size)
        for _ in range(max_iter):
            g, dg = log_ngamma_slope(x, al, ph, ss)
            pos = g > 0.0
            b = np.where(pos, x, b)
            a = np.where(pos, a, x)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = x - g / dg
            ok = (dg > 0.0) & (newton > a) & (newton < b)
            x_new = np.where(ok, newton, 0.5 * (a + b))
            going = np.abs(x_new - x) >= tol
            out[active] = x_new
            if not going.any():
                break
            if not going.all():
                active, x_new, a, b, al, ph, ss = (v[going] for v in (active, x_new, a, b, al, ph, ss))
            x = x_new
        beta[inner] = out
    return beta


def optimal_beta_scalar(alpha: float, rho: float, phi: float, delta: float,
                        options: ModelOptions = DEFAULT_OPTIONS, guess: float | None = None) -> float:
    """Scalar fast path of :func:`optimal_beta` (pure ``math``), optionally warm-started."""
    s = rho + delta + phi
    lo = options.eps1
    hi = min(math.pi - s - options.eps2, 0.5 * math.pi - alpha)
    tan = math.tan
    g = -tan(alpha + lo) + 1.0 / tan(alpha + lo + phi) - 1.0 / tan(lo) - 1.0 / tan(lo + s)
    if g >= 0.0:
        return lo
    g = -tan(alpha + hi) + 1.0 / tan(alpha + hi + phi) - 1.0 / tan(hi) - 1.0 / tan(hi + s)
    if g <= 0.0:
        return hi
    a, b = lo, hi
    x = guess if guess is not None and lo < guess < hi else 0.5 * (lo + hi)
    for _ in range(60):
        t1 = tan(alpha + x)
        c2 = 1.0 / tan(alpha + x + phi)
        c3 = 1.0 / tan(x)
        c4 = 1.0 / tan(x + s)
        g = -t1 + c2 - c3 - c4
        if g > 0.0:
            b = x
        else:
            a = x
        dg = -t1 * t1 - c2 * c2 + c3 * c3 + c4 * c4
        xn = x - g / dg if dg > 0.0 else a - 1.0
        if not a < xn < b:
            xn = 0.5 * (a + b)
        if abs(xn - x) < 1e-11:
            return xn
        x = xn
    return x


# ----------------------------------------------------------------- forces
@dataclass(frozen=True, eq=False)
class SoilForces:
    """Model output per sample (all arrays of the path's length).

    Attributes
    ----------
    tangential, normal, resultant : numpy.ndarray
        F_T (eq 16), F_N (eq 17) and F_R = sqrt(F_T^2 + F_N^2) [N].
    fee_force : numpy.ndarray
        F of eq 1 after the tension clamp [N].
    pressure : numpy.ndarray
        Bekker penetration pressure P (eq 15) [Pa].
    beta : numpy.ndarray
        Failure angle beta* [rad].
    n_gamma, n_c, n_a, n_q : numpy.ndarray
        Bearing capacity factors at beta* (eqs 10-13).
    flags : numpy.ndarray
        Bitwise OR of ``FLAG_*`` per sample (0 = inside the validity domain).
    """

    tangential: np.ndarray
    normal: np.ndarray
    resultant: np.ndarray
    fee_force: np.ndarray
    pressure: np.ndarray
    beta: np.ndarray
    n_gamma: np.ndarray
    n_c: np.ndarray
    n_a: np.ndarray
    n_q: np.ndarray
    flags: np.ndarray = field(repr=False)

    @property
    def valid(self) -> np.ndarray:
        """True where the sample is in soil and inside the validity domain."""
        return self.flags == 0

    def flag_summary(self) -> dict[str, int]:
        """Count of samples per flag name."""
        return {name: int(np.count_nonzero(self.flags & bit)) for bit, name in FLAG_NAMES.items()}


def soil_forces(soil: SoilParams, state: ContactState, bucket: Bucket,
                options: ModelOptions = DEFAULT_OPTIONS) -> SoilForces:
    """Forces of the modified FEE along a path (vectorised).

    Parameters
    ----------
    soil : SoilParams
        Soil parameters.
    state : ContactState
        Per-sample depth, blade angle, slope, blade length in soil and bucket
        load from :func:`wheelloader.estimator.kinematics.contact_state`.
    bucket : Bucket
        Bucket (width w, edge thickness b).
    options : ModelOptions
        Validity-domain margins.

    Returns
    -------
    SoilForces
    """
    phi, delta = soil.phi, soil.delta
    alpha, rho, flags = clamp_angles(state.alpha, state.rho, phi, delta, options)
    beta = optimal_beta(alpha, rho, phi, delta, options)
    n_gamma, n_c, n_a, n_q = bearing_factors(alpha, rho, beta, phi, delta)
    n_gamma = np.maximum(n_gamma, 0.0)
    d = state.depth
    out = d <= 0.0
    flags = flags | np.where(out, FLAG_OUT_OF_SOIL, 0)
    d = np.where(out, 0.0, d)
    w = bucket.width
    w_load = state.load_weight(soil.gamma)
    ramp = np.minimum(d / options.contact_depth, 1.0)
    fee = (d * d * w * soil.gamma * GRAVITY * n_gamma + soil.cohesion * w * d * n_c
           + soil.adhesion * w * d * n_a + ramp * w_load * n_q)  # eq 1
    tension = fee < 0.0
    flags = flags | np.where(tension & ~out, FLAG_TENSION, 0)
    fee = np.maximum(fee, 0.0)
    pressure = soil.sinkage_modulus(bucket.edge_thickness) * np.power(d, soil.n)  # eq 15
    tangential = (w * bucket.edge_thickness * pressure + fee * math.sin(delta)
                  + soil.adhesion * w * state.blade_length)  # eq 16
    normal = fee * math.cos(delta)  # eq 17
    flags = np.where(out, FLAG_OUT_OF_SOIL, flags)  # out of soil: other flags are moot
    return SoilForces(tangential, normal, np.hypot(tangential, normal), fee, pressure, beta,
                      n_gamma, n_c, n_a, n_q, flags)


def soil_forces_single(soil: SoilParams, depth: float, rho: float, alpha: float, blade_length: float,
                       load_weight: float, bucket: Bucket, options: ModelOptions = DEFAULT_OPTIONS,
                       beta_guess: float | None = None) -> tuple[float, float, float, int]:
    """Fast scalar path for one sample (environment steps).

    Returns
    -------
    tuple
        ``(F_T, F_N, beta, flags)``; same equations and clamps as :func:`soil_forces`.
    """
    if depth <= 0.0:
        return 0.0, 0.0, options.eps1, FLAG_OUT_OF_SOIL
    phi, delta = soil.phi, soil.delta
    flags = 0
    rho_hi = math.pi - options.eps1 - options.eps2 - delta - phi
    if rho < options.rho_min:
        rho, flags = options.rho_min, flags | FLAG_RHO_LOW
    elif rho > rho_hi:
        rho, flags = rho_hi, flags | FLAG_RHO_HIGH
    if alpha > options.alpha_max:
        alpha, flags = options.alpha_max, flags | FLAG_ALPHA_CLAMPED
    elif alpha < -options.alpha_max:
        alpha, flags = -options.alpha_max, flags | FLAG_ALPHA_CLAMPED
    beta = optimal_beta_scalar(alpha, rho, phi, delta, options, beta_guess)
    s_beta = math.sin(rho + delta + beta + phi)
    sin_beta = math.sin(beta)
    sab = math.sin(alpha + beta + phi)
    n_gamma = max(math.cos(alpha + beta) * sab / (2.0 * math.cos(alpha) * sin_beta * s_beta), 0.0)
    n_c = math.cos(phi) / (sin_beta * s_beta)
    n_a = -math.cos(rho + beta + phi) / (math.sin(rho) * s_beta)
    n_q = sab / s_beta
    w = bucket.width
    ramp = depth / options.contact_depth
    if ramp > 1.0:
        ramp = 1.0
    fee = (depth * depth * w * soil.gamma * GRAVITY * n_gamma + soil.cohesion * w * depth * n_c
           + soil.adhesion * w * depth * n_a + ramp * load_weight * n_q)
    if fee < 0.0:
        fee, flags = 0.0, flags | FLAG_TENSION
    b = bucket.edge_thickness
    pressure = (soil.k_c / b + soil.k_phi) * depth ** soil.n
    f_t = w * b * pressure + fee * math.sin(delta) + soil.adhesion * w * blade_length
    return f_t, fee * math.cos(delta), beta, flags
