"""The modified FEE force model (paper eqs 1, 10-17) as CasADi expressions.

The same equations as :func:`wheelloader.estimator.soil_forces`, written so
that IPOPT can differentiate them twice:

* The failure angle beta* (eq 14: minimise N_gamma with ``beta >= eps1`` and
  ``|rho + delta + beta + phi - pi| >= eps2``) is not a closed-form function.
  The planner unrolls :data:`NEWTON_STEPS` guarded Newton steps on
  ``d ln N_gamma / d beta = 0`` from the middle of the valid branch, clipped
  to the branch after each step (smooth clamps, 1e-3 rad wide), as the NumPy
  solver does (without its bisection fallback). Where beta* lies on a bound the step runs past it and
  the clip returns it there. On the operating range this reproduces beta*
  closely; the gap in the forces is measured by ``tests/test_planner.py`` and
  ``benchmarks/planner.py``.
* The clamps of the validity domain become smooth: the blade angle rho is
  clipped into ``[rho_min, rho_hi]`` and the slope alpha into
  ``[-min(phi - slope_margin, alpha_max), alpha_max]`` with smooth clamps before the factors
  are evaluated, depth is a smooth positive part, and ``F >= 0`` and
  ``L_t <= floor length`` are smooth max/min, and a tanh gate over the first
  millimetre of depth switches every term off above the surface. Inside the validity domain
  (where the planner's constraints keep the path) these agree with the
  NumPy model to the smoothing widths below.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from wheelloader.estimator import DEFAULT_OPTIONS, GRAVITY, Bucket, ModelOptions, SoilParams
from wheelloader.estimator.failure_angle import beta_bounds, unrolled_beta
from wheelloader.estimator.failure_angle_weight import unrolled_beta_weight_force
from wheelloader.estimator.soil_vector import SOIL_VECTOR_NAMES
from wheelloader.estimator.soil_vector import soil_vector as estimator_soil_vector
from wheelloader.estimator.validity import alpha_lower_limit

#: Guarded Newton steps from the middle of the valid branch.
NEWTON_STEPS = 8
#: Guarded Newton steps of the opt-in least-weight-force beta*, from the middle of the branch (5 steps: the
#: weight force within 0.4 % of its minimum on 2 x 10^4 random configurations, within 3e-5 at the 99th percentile).
WEIGHT_FORCE_STEPS = 5
#: Order of the soil parameter vector the CasADi model takes (the estimator's soil vector; K = k_c/b + k_phi).
SOIL_VECTOR = SOIL_VECTOR_NAMES
#: Smoothing widths: depth [m], angle clamps [rad], force clamp [N], length clamp [m].
SMOOTH_DEPTH = 1e-4
#: Regularisation depth of d^n in eq 15 [m].
BEKKER_D0 = 2e-3
#: Width of the tanh gate that switches every term off above the surface [m].
CONTACT_GATE = 1e-3
SMOOTH_ANGLE = 1e-3
SMOOTH_FORCE = 1.0
SMOOTH_LENGTH = 1e-3


def soil_vector(soil: SoilParams, bucket: Bucket) -> np.ndarray:
    """The soil as the planner's parameter vector (order :data:`SOIL_VECTOR`); only ``k_c/b + k_phi`` enters."""
    return estimator_soil_vector(soil, bucket.edge_thickness)


def smooth_pos(v, eps):
    """Smooth ``max(v, 0)``: ``(v + sqrt(v^2 + eps^2)) / 2``."""
    return 0.5 * (v + ca.sqrt(v * v + eps * eps))


def smooth_max(a, b, eps):
    """Smooth ``max(a, b)``."""
    return b + smooth_pos(a - b, eps)


def local_max(a, b, eps):
    """C1 ``max(a, b)`` that equals it exactly where ``|a - b| >= eps`` (a quadratic blend in between)."""
    d = a - b
    return ca.if_else(d >= eps, a, ca.if_else(d <= -eps, b, b + (d + eps) ** 2 / (4.0 * eps)))


def smooth_min(a, b, eps):
    """Smooth ``min(a, b)``."""
    return a - smooth_pos(a - b, eps)


def casadi_forces(soil, vertical_depth, rho, alpha, load_weight, bucket: Bucket,
                  options: ModelOptions = DEFAULT_OPTIONS, carried_weight=None) -> dict[str, ca.SX]:
    """F_T and F_N (eqs 16-17) as CasADi expressions.

    Parameters
    ----------
    soil : casadi.SX
        Soil vector in the order :data:`SOIL_VECTOR` (symbolic or numeric).
    vertical_depth : casadi.SX
        Surface height minus tip height [m] (negative above the surface).
    rho, alpha : casadi.SX
        Blade angle relative to the surface and local slope [rad].
    load_weight : casadi.SX
        Soil weight in the bucket W_load [N].
    bucket : Bucket
        Width and edge thickness (constants of the solver).
    options : ModelOptions
        Validity-domain margins; with ``carried_load`` (the ``"fee-payload"`` force model) the carried load's
        weight is added as :func:`~wheelloader.estimator.force_model.carried_forces` adds it (weight only, no
        inertia), ramped in as the tip leaves the soil when ``carried_in_soil`` is False, and not gated out of
        the soil.
    carried_weight : casadi.SX, optional
        Weight of the carried load [N] (the payload's kept soil); default ``load_weight``.

    Returns
    -------
    dict
        ``F_T``, ``F_N`` [N], ``depth`` [m], ``beta`` [rad], ``fee`` [N].
    """
    gamma, cohesion, adhesion, phi, delta, modulus, n = (soil[i] for i in range(7))
    w, b = bucket.width, bucket.edge_thickness
    # the down-slope limit follows phi; its clamp is exact (C1) beyond SMOOTH_ANGLE so slopes far from it are untouched
    alpha_lo = alpha_lower_limit(phi, options, minimum=lambda a, b: smooth_min(a, b, SMOOTH_ANGLE))
    alpha_c = smooth_min(local_max(alpha, alpha_lo, SMOOTH_ANGLE), options.alpha_max, SMOOTH_ANGLE)
    rho_hi = math.pi - options.eps1 - options.eps2 - delta - phi
    rho_c = smooth_min(smooth_max(rho, options.rho_min, SMOOTH_ANGLE), rho_hi, SMOOTH_ANGLE)
    depth = smooth_pos(vertical_depth, SMOOTH_DEPTH) * ca.cos(alpha)
    s = rho_c + delta + phi
    lo, hi = beta_bounds(alpha_c, rho_c, phi, delta, options, minimum=lambda a, b: smooth_min(a, b, SMOOTH_ANGLE))
    clip = lambda v, a, b: smooth_min(smooth_max(v, a, SMOOTH_ANGLE), b, SMOOTH_ANGLE)  # noqa: E731
    ramp = smooth_min(depth / options.contact_depth, 1.0, 1e-3)
    if options.failure_angle == "min_weight_force":  # opt-in (estimator.failure_angle); V_fill = W_load/(gamma g)
        surcharge = ramp * load_weight / (gamma * GRAVITY * w)
        beta = unrolled_beta_weight_force(0.5 * (lo + hi), alpha_c, rho_c, phi, delta, depth * depth, surcharge,
                                          lo, hi, WEIGHT_FORCE_STEPS, sin=ca.sin, cos=ca.cos, clip=clip,
                                          positive=lambda dg: smooth_max(dg, 0.1, 0.01))
    else:
        beta = unrolled_beta(alpha_c, phi, s, lo, hi, NEWTON_STEPS, tan=ca.tan, clip=clip,
                             positive=lambda dg: smooth_max(dg, 1.0, 0.1))
    s_beta = ca.sin(s + beta)
    sin_beta = ca.sin(beta)
    sab = ca.sin(alpha_c + beta + phi)
    n_gamma = smooth_pos(ca.cos(alpha_c + beta) * sab / (2.0 * ca.cos(alpha_c) * sin_beta * s_beta), 1e-6)  # eq 10
    n_gamma = n_gamma + options.wedge_offset  # the opt-in offset (ModelOptions.wedge_offset)
    n_c = ca.cos(phi) / (sin_beta * s_beta)  # eq 11
    n_a = -ca.cos(rho_c + beta + phi) / (ca.sin(rho_c) * s_beta)  # eq 12
    n_q = sab / s_beta  # eq 13
    fee = (depth * depth * w * gamma * GRAVITY * n_gamma + cohesion * w * depth * n_c
           + adhesion * w * depth * n_a + ramp * load_weight * n_q)  # eq 1
    fee = smooth_pos(fee, SMOOTH_FORCE)
    # eq 15 with d^n regularised as (d^2 + d0^2)^(n/2): d^n has an infinite slope at d = 0 when n < 1,
    # which wrecks IPOPT's Hessian; the two differ by < 0.1 % beyond 3 cm of depth (d0 = 2 mm)
    pressure = modulus * ca.exp(0.5 * n * ca.log(depth * depth + BEKKER_D0 * BEKKER_D0))
    sin_rho = smooth_max(ca.sin(rho), math.sin(math.radians(10.0)), 1e-3)
    blade_length = smooth_min(depth / sin_rho, bucket.floor_length, SMOOTH_LENGTH)
    # out of soil the model's forces are 0; d^n with n < 1 is steep at d = 0, so gate every term
    gate = 0.5 * (1.0 + ca.tanh(vertical_depth / CONTACT_GATE))
    f_t = gate * (w * b * pressure + fee * ca.sin(delta) + adhesion * w * blade_length)  # eq 16
    f_n = gate * fee * ca.cos(delta)  # eq 17
    if options.carried_load:  # the carried load's weight in the blade frame (force_model.carried_forces)
        carried = load_weight if carried_weight is None else carried_weight
        if not options.carried_in_soil:  # handed over from the surcharge as the tip leaves the soil
            carried = (1.0 - ramp) * carried
        theta = alpha - rho
        f_t = f_t + carried * ca.sin(theta)
        f_n = f_n + carried * ca.cos(theta)
    return {"F_T": f_t, "F_N": f_n, "depth": depth, "beta": beta, "fee": fee, "gate": gate}


#: Speed below which the planner's tip speed is smoothed [m/s] (``sqrt(v^2 + eps^2)``: differentiable at rest).
SMOOTH_SPEED = 1e-3


def casadi_learned(soil, depth, rho, alpha, blade_angle, carved, kept, vx, vz, bucket: Bucket) -> tuple:
    """The learned correction of ``force_model="fee-learned"`` (``F_T``, ``F_N`` [N]) as CasADi expressions.

    The inputs of :func:`~wheelloader.estimator.learned.learned_inputs` (``depth`` the perpendicular depth of
    :func:`casadi_forces`, ``carved`` and ``kept`` the carved and the kept fill [m^3], ``vx, vz`` the tip velocity
    [m/s]) through the network's CasADi twin :func:`~wheelloader.estimator.learned.casadi_correction` (the same
    clip, standardisation and layers; exact derivatives), times ``s = gamma g w L^2``. The contact ramp is the
    smooth min of :func:`casadi_forces` (1e-3 wide) and the speed ``sqrt(v^2 + SMOOTH_SPEED^2)``.
    """
    from wheelloader.estimator.learned import CONTACT_DEPTH, casadi_correction, default_learned_model

    gamma, cohesion, adhesion, phi, delta = (soil[i] for i in range(5))
    length = bucket.floor_length
    weight = gamma * GRAVITY * length
    speed = ca.sqrt(vx * vx + vz * vz + SMOOTH_SPEED * SMOOTH_SPEED)
    x = ca.horzcat(depth / length, smooth_min(depth / CONTACT_DEPTH, 1.0, 1e-3), rho, alpha, blade_angle,
                   carved / bucket.capacity, kept / bucket.capacity, speed / math.sqrt(GRAVITY * length),
                   ca.tan(phi), ca.tan(delta), cohesion / weight, adhesion / weight)
    r = casadi_correction(default_learned_model(), x) * (gamma * GRAVITY * bucket.width * length * length)
    return r[0], r[1]


def learned_trust(bucket: Bucket) -> tuple[float, float]:
    """The deepest cut [m] and the fastest tip speed [m/s] inside the learned correction's training range (the
    top of its ``depth_over_length`` and ``froude`` inputs): the planner keeps ``"fee-learned"`` plans within
    them. Beyond them the correction is held at the range's edge, and at that kink IPOPT stopped converging
    (``benchmarks/force_model_costs.py``: every cold plan ran to ``max_iter`` without the limits)."""
    from wheelloader.estimator.learned import INPUT_NAMES, default_learned_model

    high = default_learned_model().high
    length = bucket.floor_length
    return (float(high[INPUT_NAMES.index("depth_over_length")]) * length,
            float(high[INPUT_NAMES.index("froude")]) * math.sqrt(GRAVITY * length))
