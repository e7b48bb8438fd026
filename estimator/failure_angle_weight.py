"""The failure angle of least weight force: the opt-in rule ``ModelOptions(failure_angle="min_weight_force")``.

With ``ModelOptions(failure_angle="min_weight_force")`` beta* minimises, on the same branch, the force of
the soil's weight instead of N_gamma alone (McKyes' rule of choosing the failure plane that needs the
least force, applied to the gravity terms of eq 1):

    h(beta) = d^2 N_gamma(beta) + q N_q(beta),     q = r V_fill / w  [m^2]

(``r`` the surcharge ramp, ``V_fill`` the bucket's fill volume, ``w`` its width), i.e. eq 1 divided by
``gamma g w`` for a cohesionless soil whose surcharge is the bucket's load. It depends on the sample's
depth and load but not on gamma, C or C_a, so the forces stay linear in them (the calibration's variable
projection holds). With an empty bucket (q = 0) it is the paper's rule. On a pile face the paper's rule
drives beta* to ``pi/2 - alpha`` where N_gamma = 0 while N_q is large, so the surcharge term ``W_load N_q``
dominates and depth costs almost nothing; the least-force plane is shallower and its N_q smaller.
``h`` has one interior minimum on the branch (checked on a grid of 2 001 angles for 2 x 10^4 random
configurations, and by hypothesis in ``tests/test_failure_angle_rules.py``). Front ends:
:func:`optimal_beta_weight_force` (NumPy) and :func:`optimal_beta_weight_force_scalar`.
"""

from __future__ import annotations

import math

import numpy as np

from .failure_angle import (
    BETA_AT_EPS1,
    BETA_AT_RHO_LIMIT,
    BETA_AT_SLOPE_LIMIT,
    BETA_INTERIOR,
    beta_bounds,
    of_shape,
    optimal_beta,
    optimal_beta_scalar,
)
from .validity import DEFAULT_OPTIONS, ModelOptions


def _root_in_bracket(slope_and_curvature, a: float, b: float, x: float, tol: float) -> float:
    """Root of an increasing-through-zero slope in ``(a, b)`` (slope < 0 at a, > 0 at b) by safeguarded Newton
    from ``x``: a step that leaves the bracket, or a curvature that is not positive, bisects instead; stops when
    a step is shorter than ``tol`` (at most 60 steps). The scalar solvers' shared loop."""
    for _ in range(60):
        g, dg = slope_and_curvature(x)
        if g > 0.0:
            b = x
        else:
            a = x
        xn = x - g / dg if dg > 0.0 else a - 1.0
        if not a <= xn <= b:  # a step onto a bracket end is kept (as the vectorised solvers do)
            xn = 0.5 * (a + b)
        if abs(xn - x) < tol:
            return xn
        x = xn
    return x


def weight_force_slope(beta, alpha, rho, phi, delta, depth_sq, surcharge, sin=np.sin, cos=np.cos):
    """``h'(beta)`` of ``h = d^2 N_gamma + q N_q`` (eqs 10, 13; module docstring); arrays broadcast.

    ``depth_sq`` is ``d^2`` [m^2], ``surcharge`` is ``q`` [m^2]; ``sin``/``cos`` of the array library.
    """
    a1, a1s = cos(alpha + beta), sin(alpha + beta)
    a2, a2c = sin(alpha + beta + phi), cos(alpha + beta + phi)
    u = rho + delta + beta + phi
    s_u, c_u = sin(u), cos(u)
    sin_b = sin(beta)
    den = 2.0 * cos(alpha) * sin_b * s_u
    n_gamma = a1 * a2 / den
    dn_gamma = (a1 * a2c - a1s * a2) / den - n_gamma * (cos(beta) / sin_b + c_u / s_u)
    dn_q = (a2c - a2 * c_u / s_u) / s_u
    return depth_sq * dn_gamma + surcharge * dn_q


def optimal_beta_weight_force(alpha, rho, phi, delta, depth, surcharge, options: ModelOptions = DEFAULT_OPTIONS,
                              tol: float = 1e-13, max_iter: int = 60, return_where: bool = False):
    """beta* of the least weight force ``h = d^2 N_gamma + q N_q`` on the valid branch (module docstring).

    Parameters
    ----------
    alpha, rho : array_like
        Clamped slope and blade angle [rad].
    phi, delta : float or array_like
        Friction angles [rad].
    depth : array_like
        Tip depth d [m] (values <= 0 count as 0).
    surcharge : array_like
        ``q = r V_fill / w`` [m^2] (>= 0).
    options : ModelOptions
        Margins eps1, eps2.
    tol, max_iter : float, int
        Newton step below which the iteration stops [rad], and its largest number of iterations.
    return_where : bool
        Also return where beta* lies (``BETA_*`` codes, as :func:`optimal_beta`).

    Returns
    -------
    numpy.ndarray or tuple
        beta* [rad]; where ``d = q = 0`` (nothing to minimise) the paper's rule (:func:`optimal_beta`).
        With ``return_where`` also the ``BETA_*`` code per sample.
    """
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (alpha, rho, phi, delta, depth, surcharge)))
    shape = arrays[0].shape
    alpha, rho, phi, delta, depth, surcharge = (np.ravel(v) for v in arrays)
    d2 = np.square(np.maximum(depth, 0.0))
    q = np.maximum(surcharge, 0.0)
    lo, hi = (of_shape(v, alpha.shape) for v in beta_bounds(alpha, rho, phi, delta, options))
    loaded = (d2 + q) > 0.0
    beta = np.array(hi, dtype=float)
    where = np.full(alpha.shape, BETA_INTERIOR)
    if not loaded.all():  # nothing to minimise: the paper's rule
        empty = ~loaded
        beta[empty], where[empty] = optimal_beta(alpha[empty], rho[empty], phi[empty], delta[empty], options,
                                                 return_where=True)
    slope_lo = weight_force_slope(lo, alpha, rho, phi, delta, d2, q)
    slope_hi = weight_force_slope(hi, alpha, rho, phi, delta, d2, q)
    at_lo = loaded & (slope_lo >= 0.0)
    at_hi = loaded & ~at_lo & (slope_hi <= 0.0)
    beta = np.where(at_lo, lo, np.where(at_hi, hi, beta))
    inner = loaded & ~(at_lo | at_hi)
    if np.any(inner):
        a, b = lo[inner], hi[inner]
        g_a, g_b = slope_lo[inner], slope_hi[inner]  # h' < 0 at a, > 0 at b
        args = [v[inner] for v in (alpha, rho, phi, delta, d2, q)]
        # Newton (curvature by central differences) inside the bracket; where its step leaves the bracket or
        # the curvature is not positive, the regula falsi point of the bracket (Illinois: the end kept twice
        # has its slope halved), so no sample falls back to plain bisection
        x = 0.5 * (a + b)
        kept = np.zeros(x.size, dtype=int)  # +1: b kept last time, -1: a kept last time
        out = np.empty_like(x)
        active = np.arange(x.size)
        step = 1e-6
        for _ in range(max_iter):
            g = weight_force_slope(x, *args)
            dg = (weight_force_slope(x + step, *args) - weight_force_slope(x - step, *args)) / (2.0 * step)
            pos = g > 0.0
            g_a = np.where(~pos & (kept == -1), g_a, np.where(pos & (kept == -1), 0.5 * g_a, g_a))
            g_b = np.where(pos & (kept == 1), g_b, np.where(~pos & (kept == 1), 0.5 * g_b, g_b))
            b, g_b = np.where(pos, x, b), np.where(pos, g, g_b)
            a, g_a = np.where(pos, a, x), np.where(pos, g_a, g)
            kept = np.where(pos, -1, 1)
            with np.errstate(divide="ignore", invalid="ignore"):
                newton = x - g / dg
                falsi = a - g_a * (b - a) / (g_b - g_a)
            # a Newton step onto a bracket end is kept: the root then sits within rounding of that end, and a
            # step strictly inside only would creep towards it (measured: ~40 iterations instead of ~12)
            ok = (dg > 0.0) & (newton >= a) & (newton <= b)
            falsi = np.where((falsi > a) & (falsi < b), falsi, 0.5 * (a + b))
            x_new = np.where(ok, newton, falsi)
            going = np.abs(x_new - x) >= tol
            out[active] = x_new
            if not going.any():
                break
            if not going.all():
                active, x_new, a, b, g_a, g_b, kept = (v[going] for v in (active, x_new, a, b, g_a, g_b, kept))
                args = [v[going] for v in args]
            x = x_new
        beta[inner] = out
    if not return_where:
        return beta.reshape(shape)
    at_rho_limit = (math.pi - (rho + delta + phi) - options.eps2) <= (0.5 * math.pi - alpha)
    bound = np.where(at_lo, BETA_AT_EPS1, np.where(at_rho_limit, BETA_AT_RHO_LIMIT, BETA_AT_SLOPE_LIMIT))
    where = np.where(at_lo | at_hi, bound, where)
    return beta.reshape(shape), where.reshape(shape)


def optimal_beta_weight_force_scalar(alpha: float, rho: float, phi: float, delta: float, depth: float,
                                     surcharge: float, options: ModelOptions = DEFAULT_OPTIONS) -> float:
    """Scalar fast path of :func:`optimal_beta_weight_force` (pure ``math``)."""
    d2 = max(depth, 0.0) ** 2
    q = max(surcharge, 0.0)
    paper = optimal_beta_scalar(alpha, rho, phi, delta, options)
    if d2 + q <= 0.0:
        return paper
    s = rho + delta + phi
    lo = options.eps1
    hi = min(math.pi - s - options.eps2, 0.5 * math.pi - alpha)
    sin, cos = math.sin, math.cos

    def slope(b: float) -> float:
        return weight_force_slope(b, alpha, rho, phi, delta, d2, q, sin, cos)

    if slope(lo) >= 0.0:
        return lo
    if slope(hi) <= 0.0:
        return hi
    step = 1e-6
    return _root_in_bracket(lambda b: (slope(b), (slope(b + step) - slope(b - step)) / (2.0 * step)),
                            lo, hi, 0.5 * (lo + hi), 1e-13)


def unrolled_beta_weight_force(start, alpha, rho, phi, delta, depth_sq, surcharge, lo, hi, steps: int, *, sin, cos,
                               clip, positive, step: float = 1e-5):
    """beta* of the least weight force by ``steps`` guarded Newton steps from ``start``, for symbolic backends.

    The curvature ``h''`` is a central difference of :func:`weight_force_slope` (``step`` [rad]); ``clip`` and
    ``positive`` as in :func:`unrolled_beta`. Scale: ``positive`` receives ``h'' / (d^2 + q)`` (dimensionless).
    """
    scale = depth_sq + surcharge + 1e-12
    beta = start
    for _ in range(steps):
        g = weight_force_slope(beta, alpha, rho, phi, delta, depth_sq, surcharge, sin, cos) / scale
        dg = (weight_force_slope(beta + step, alpha, rho, phi, delta, depth_sq, surcharge, sin, cos)
              - weight_force_slope(beta - step, alpha, rho, phi, delta, depth_sq, surcharge, sin, cos)) / (2 * step)
        beta = clip(beta - g / positive(dg / scale), lo, hi)
    return beta
