"""The modified Fundamental Earthmoving Equation (paper Section II).

Forces on the bucket blade from the soil wedge (eq 1), with the bearing
capacity factors in the canonical sine-cosine form (eqs 10-13), the failure
angle beta chosen by minimising N_gamma under the continuity constraints of
eq 14, Bekker's penetration pressure (eq 15) and the blade-frame forces
F_T, F_N (eqs 16-17).

Validity domain (README "Validity domain")
------------------------------------------
The angle clamps and flags are in :mod:`~wheelloader.estimator.validity`
(``rho`` in ``[rho_min, pi - eps1 - eps2 - delta - phi]``, ``alpha`` in
``[-min(phi - slope_margin, alpha_max), alpha_max]``), beta* on the valid branch in
:mod:`~wheelloader.estimator.failure_angle`. Here:

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

Opt-in term beyond the paper: the carried load
------------------------------------------------
With ``ModelOptions(carried_load=True)`` the soil already in the bucket (mass
``m = W_load / g``) adds the force it exerts on the bucket, ``m (g_vec - a)``
(weight, and inertia when the tip acceleration ``a`` is known), resolved in
the blade frame of eqs 16-17 (:func:`carried_load_factors`): with the blade
angle theta above +x,

    F_T += W_load (a_x cos theta + (g + a_z) sin theta) / g,
    F_N += W_load ((g + a_z) cos theta - a_x sin theta) / g,

in and out of soil (after the tip leaves the soil the bucket still carries
its load). A tip pointing down (theta < 0) makes the weight's share of F_T
negative, so F_T can be negative with this term. ``W_load`` is the same
load as the surcharge's (``gamma g V_fill`` or the logged load), so the
forces stay linear in gamma.

Opt-in term beyond the paper: slip-mobilised blade friction
-----------------------------------------------------------
With ``ModelOptions(slip_friction=True)`` the blade friction and adhesion
(``F sin(delta) + C_a w L_t`` in eq 16) are scaled by :func:`slip_factor`
``m = (max(v_a, 0) + v_0) / (|v| + v_0)``, the share of the tip's motion that
slides the soil along the blade: friction acts against slip, and a blade moving
along its own normal (lifting its load out of the cut) slides little soil along
itself. ``m = 1`` at standstill and when advancing along the blade (the paper's
model). The forces stay linear in gamma, C, C_a and K.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from .failure_angle import (
    beta_bounds,
    log_ngamma_slope,
    optimal_beta,
    optimal_beta_scalar,
)
from .failure_angle_weight import optimal_beta_weight_force, optimal_beta_weight_force_scalar
from .kinematics import ContactState
from .machine import Bucket
from .soil import SoilParams
from .validity import (
    DEFAULT_OPTIONS,
    FLAG_ALPHA_CLAMPED,
    FLAG_NAMES,
    FLAG_OUT_OF_SOIL,
    FLAG_RHO_HIGH,
    FLAG_RHO_LOW,
    FLAG_TENSION,
    ModelOptions,
    clamp_angles,
)

__all__ = [
    "DEFAULT_OPTIONS", "FLAG_ALPHA_CLAMPED", "FLAG_NAMES", "FLAG_OUT_OF_SOIL", "FLAG_RHO_HIGH", "FLAG_RHO_LOW",
    "FLAG_TENSION", "GRAVITY", "ModelOptions", "SoilForces", "bearing_factors", "bearing_factors_cotangent",
    "beta_bounds", "carried_forces", "carried_load_factors", "clamp_angles", "log_ngamma_slope", "optimal_beta",
    "optimal_beta_scalar", "slip_factor", "soil_forces", "soil_forces_single",
]

#: Standard gravity [m/s^2].
GRAVITY = 9.81


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
    sab = np.sin(alpha + beta + phi)  # in eqs 10 and 13
    n_gamma = np.cos(alpha + beta) * sab / (2.0 * np.cos(alpha) * sin_beta * s_beta)  # eq 10
    n_c = math.cos(phi) / (sin_beta * s_beta) if np.ndim(phi) == 0 else np.cos(phi) / (sin_beta * s_beta)  # eq 11
    n_a = -np.cos(rho + beta + phi) / (np.sin(rho) * s_beta)  # eq 12 (sin(beta+phi) cancelled)
    n_q = sab / s_beta  # eq 13
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


def carried_load_factors(blade_angle, acceleration=None) -> tuple[np.ndarray, np.ndarray]:
    """Blade-frame force of a carried load per newton of its weight: ``(c_T, c_N)`` (module docstring).

    Parameters
    ----------
    blade_angle : array_like
        Blade direction above +x [rad].
    acceleration : array_like, optional
        Tip acceleration ``(a_x, a_z)``, shape ``(n, 2)`` [m/s^2]; None: weight only.

    Returns
    -------
    tuple of numpy.ndarray
        ``c_T = (a_x cos theta + (g + a_z) sin theta) / g``, ``c_N = ((g + a_z) cos theta - a_x sin theta) / g``.
    """
    th = np.asarray(blade_angle, dtype=float)
    c, s = np.cos(th), np.sin(th)
    if acceleration is None:
        return s, c
    acc = np.asarray(acceleration, dtype=float)
    ax, gz = acc[:, 0] / GRAVITY, 1.0 + acc[:, 1] / GRAVITY
    return ax * c + gz * s, gz * c - ax * s


def slip_factor(blade_angle, velocity=None, slip_speed: float = 0.05) -> np.ndarray:
    """Share of the blade friction mobilised by slip along the blade (module docstring), in [0, 1].

    Parameters
    ----------
    blade_angle : array_like
        Blade direction above +x [rad].
    velocity : array_like, optional
        Tip velocity ``(v_x, v_z)``, shape ``(n, 2)`` [m/s]; None: standing still (factor 1).
    slip_speed : float
        ``v_0`` [m/s].
    """
    th = np.asarray(blade_angle, dtype=float)
    if velocity is None:
        return np.ones_like(th)
    vel = np.asarray(velocity, dtype=float)
    along = vel[:, 0] * np.cos(th) + vel[:, 1] * np.sin(th)
    return (np.maximum(along, 0.0) + slip_speed) / (np.hypot(vel[:, 0], vel[:, 1]) + slip_speed)


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


def carried_forces(depth, blade_angle, carried_weight, acceleration=None,
                   options: ModelOptions = DEFAULT_OPTIONS) -> tuple[np.ndarray, np.ndarray]:
    """The opt-in carried-load term's ``(dF_T, dF_N)`` [N] (module docstring), in and out of soil.

    The one vectorised form of the term: :func:`soil_forces` adds it, and so does the batched env to every row
    (in soil and out of it) under the ``"fee-payload"`` force model.

    Parameters
    ----------
    depth : array_like
        Tip depth [m] (<= 0: out of soil).
    blade_angle : array_like
        Blade direction above +x [rad] (``alpha - rho``).
    carried_weight : array_like
        Weight of the carried load [N].
    acceleration : array_like, optional
        Tip acceleration ``(a_x, a_z)``, shape ``(n, 2)`` [m/s^2]; None: weight only.
    options : ModelOptions
        ``carried_in_soil`` False hands the weight over from the surcharge as the tip leaves the soil,
        ``1 - min(d / contact_depth, 1)``.
    """
    c_t, c_n = carried_load_factors(blade_angle, acceleration)
    w_carried = np.asarray(carried_weight, dtype=float)
    if not options.carried_in_soil:  # handed over from the surcharge as the tip leaves (ModelOptions)
        ramp = np.minimum(np.maximum(np.asarray(depth, dtype=float), 0.0) / options.contact_depth, 1.0)
        w_carried = (1.0 - ramp) * w_carried
    return w_carried * c_t, w_carried * c_n


def soil_forces(soil: SoilParams, state: ContactState, bucket: Bucket,
                options: ModelOptions = DEFAULT_OPTIONS, beta_guess: np.ndarray | None = None) -> SoilForces:
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
    beta_guess : numpy.ndarray, optional
        Warm start of the failure angle per sample (e.g. the previous step's; used where it lies inside the
        bracket), as :func:`soil_forces_single` takes one: the same root within the solver's tolerance, in
        fewer iterations.

    Returns
    -------
    SoilForces
    """
    phi, delta = soil.phi, soil.delta
    alpha, rho, flags = clamp_angles(state.alpha, state.rho, phi, delta, options)
    d = state.depth
    out = d <= 0.0
    flags = flags | np.where(out, FLAG_OUT_OF_SOIL, 0)
    d = np.where(out, 0.0, d)
    w = bucket.width
    ramp = np.minimum(d / options.contact_depth, 1.0)
    if options.failure_angle == "min_weight_force":  # opt-in (failure_angle_weight module docstring)
        beta = optimal_beta_weight_force(alpha, rho, phi, delta, d, ramp * state.fill_volume / w, options)
    else:
        beta = optimal_beta(alpha, rho, phi, delta, options, guess=beta_guess)  # eq 14
    n_gamma, n_c, n_a, n_q = bearing_factors(alpha, rho, beta, phi, delta)
    n_gamma = np.maximum(n_gamma, 0.0) + options.wedge_offset  # eq 10; the opt-in offset (ModelOptions)
    w_load = state.load_weight(soil.gamma)
    fee = (d * d * w * soil.gamma * GRAVITY * n_gamma + soil.cohesion * w * d * n_c
           + soil.adhesion * w * d * n_a + ramp * w_load * n_q)  # eq 1
    tension = fee < 0.0
    flags = flags | np.where(tension & ~out, FLAG_TENSION, 0)
    fee = np.maximum(fee, 0.0)
    pressure = soil.sinkage_modulus(bucket.edge_thickness) * np.power(d, soil.n)  # eq 15
    if options.slip_friction:  # opt-in: friction mobilised by slip along the blade (module docstring)
        friction = fee * math.sin(delta) + soil.adhesion * w * state.blade_length
        friction = friction * slip_factor(state.blade_angle, state.velocity, options.slip_speed)
        tangential = w * bucket.edge_thickness * pressure + friction
    else:
        tangential = (w * bucket.edge_thickness * pressure + fee * math.sin(delta)
                      + soil.adhesion * w * state.blade_length)  # eq 16
    normal = fee * math.cos(delta)  # eq 17
    if options.carried_load:  # opt-in: the carried load's weight and inertia (module docstring)
        d_t, d_n = carried_forces(state.depth, state.blade_angle, state.carried_weight(soil.gamma),
                                  state.acceleration, options)
        tangential = tangential + d_t
        normal = normal + d_n
    flags = np.where(out, FLAG_OUT_OF_SOIL, flags)  # out of soil: other flags are moot
    return SoilForces(tangential, normal, np.hypot(tangential, normal), fee, pressure, beta,
                      n_gamma, n_c, n_a, n_q, flags)


@functools.lru_cache(maxsize=32)
def _without_carried(options: ModelOptions) -> ModelOptions:
    """``options`` with the carried-load term off (made once per options: the env's steps call it)."""
    return replace(options, carried_load=False)


def soil_forces_single(soil: SoilParams, depth: float, rho: float, alpha: float, blade_length: float,
                       load_weight: float, bucket: Bucket, options: ModelOptions = DEFAULT_OPTIONS,
                       beta_guess: float | None = None,
                       acceleration: tuple[float, float] = (0.0, 0.0),
                       velocity: tuple[float, float] = (0.0, 0.0),
                       carried_weight: float | None = None) -> tuple[float, float, float, int]:
    """Fast scalar path for one sample (environment steps).

    ``acceleration`` (tip ``(a_x, a_z)`` [m/s^2]) is used only by the opt-in carried-load term,
    ``velocity`` (tip ``(v_x, v_z)`` [m/s]) only by the opt-in slip-friction term. ``carried_weight`` [N] is
    the carried load's weight when it differs from ``load_weight`` (the payload's kept soil,
    :attr:`ContactState.carried_volume`); None: ``load_weight``.

    Returns
    -------
    tuple
        ``(F_T, F_N, beta, flags)``; same equations and clamps as :func:`soil_forces`.
    """
    if options.carried_load:
        f_t, f_n, beta, flags = soil_forces_single(soil, depth, rho, alpha, blade_length, load_weight, bucket,
                                                   _without_carried(options), beta_guess, velocity=velocity)
        theta = alpha - rho
        ax, gz = acceleration[0] / GRAVITY, 1.0 + acceleration[1] / GRAVITY
        c_t = ax * math.cos(theta) + gz * math.sin(theta)
        c_n = gz * math.cos(theta) - ax * math.sin(theta)
        w_carried = load_weight if carried_weight is None else carried_weight
        if not options.carried_in_soil:  # handed over from the surcharge as the tip leaves (ModelOptions)
            w_carried = (1.0 - min(max(depth, 0.0) / options.contact_depth, 1.0)) * w_carried
        return f_t + w_carried * c_t, f_n + w_carried * c_n, beta, flags
    if depth <= 0.0:
        return 0.0, 0.0, options.eps1, FLAG_OUT_OF_SOIL
    alpha_in, rho_in = alpha, rho
    phi, delta = soil.phi, soil.delta
    flags = 0
    rho_hi = math.pi - options.eps1 - options.eps2 - delta - phi
    if rho < options.rho_min:
        rho, flags = options.rho_min, flags | FLAG_RHO_LOW
    elif rho > rho_hi:
        rho, flags = rho_hi, flags | FLAG_RHO_HIGH
    alpha_lo = options.slope_margin - phi  # validity.alpha_lower_limit
    if alpha_lo < -options.alpha_max:
        alpha_lo = -options.alpha_max
    if alpha > options.alpha_max:
        alpha, flags = options.alpha_max, flags | FLAG_ALPHA_CLAMPED
    elif alpha < alpha_lo:
        alpha, flags = alpha_lo, flags | FLAG_ALPHA_CLAMPED
    w = bucket.width
    ramp = depth / options.contact_depth
    if ramp > 1.0:
        ramp = 1.0
    if options.failure_angle == "min_weight_force":  # opt-in; V_fill = W_load / (gamma g) here
        surcharge = ramp * load_weight / (soil.gamma * GRAVITY * w) if soil.gamma > 0.0 else 0.0
        beta = optimal_beta_weight_force_scalar(alpha, rho, phi, delta, depth, surcharge, options)
    else:
        beta = optimal_beta_scalar(alpha, rho, phi, delta, options, beta_guess)
    s_beta = math.sin(rho + delta + beta + phi)
    sin_beta = math.sin(beta)
    sab = math.sin(alpha + beta + phi)
    n_gamma = max(math.cos(alpha + beta) * sab / (2.0 * math.cos(alpha) * sin_beta * s_beta), 0.0)
    n_gamma += options.wedge_offset  # the opt-in offset (ModelOptions.wedge_offset)
    n_c = math.cos(phi) / (sin_beta * s_beta)
    n_a = -math.cos(rho + beta + phi) / (math.sin(rho) * s_beta)
    n_q = sab / s_beta
    fee = (depth * depth * w * soil.gamma * GRAVITY * n_gamma + soil.cohesion * w * depth * n_c
           + soil.adhesion * w * depth * n_a + ramp * load_weight * n_q)
    if fee < 0.0:
        fee, flags = 0.0, flags | FLAG_TENSION
    b = bucket.edge_thickness
    pressure = (soil.k_c / b + soil.k_phi) * depth ** soil.n
    if options.slip_friction:
        theta = alpha_in - rho_in
        along = velocity[0] * math.cos(theta) + velocity[1] * math.sin(theta)
        friction = fee * math.sin(delta) + soil.adhesion * w * blade_length
        friction *= (max(along, 0.0) + options.slip_speed) / (math.hypot(velocity[0], velocity[1])
                                                               + options.slip_speed)
        f_t = w * b * pressure + friction
    else:
        f_t = w * b * pressure + fee * math.sin(delta) + soil.adhesion * w * blade_length
    return f_t, fee * math.cos(delta), beta, flags
