"""The bearing factors at the failure angle beta* and their derivatives, for fitting (:mod:`.fitmodel`).

For fixed ``(phi, delta)`` beta* depends only on the sample geometry (alpha, rho), so the factors
N_gamma, N_c, N_a, N_q of eq 1 are computed once per ``(phi, delta)`` for all samples; with
``derivatives`` their total derivatives w.r.t. phi and delta (through beta*) give the analytic Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..failure_angle import (
    BETA_AT_RHO_LIMIT,
    BETA_AT_SLOPE_LIMIT,
    BETA_INTERIOR,
    optimal_beta,
)
from ..failure_angle_weight import optimal_beta_weight_force, weight_force_slope
from ..force_model import DEFAULT_OPTIONS, ModelOptions
from ..validity import clamp_details

__all__ = ["FD_STEP", "Factors", "factors"]

#: Step [rad] of the central differences of the weight force's slope (least-weight-force failure angle).
FD_STEP = 1e-6


@dataclass(frozen=True, eq=False)
class Factors:
    """Bearing factors at beta* and their total derivatives w.r.t. phi and delta (arrays, broadcast shape)."""

    n_gamma: np.ndarray
    n_c: np.ndarray
    n_a: np.ndarray
    n_q: np.ndarray
    flags_rho: np.ndarray
    d_phi: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
    d_delta: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None


def _beta_star_derivatives(alpha_e, rho_e, beta, where, phi, delta, A2, A2c, cot_b, drho, dalpha, depth, surcharge):
    """``(d beta*/d phi, d beta*/d delta)`` of :func:`factors` (its docstring); ``depth`` None: the paper's
    rule (min N_gamma), else the weight-force rule at these depths and surcharges."""
    # d beta* / d phi and / d delta
    s_tot = rho_e + delta + phi
    with np.errstate(divide="ignore", invalid="ignore"):
        # sin(alpha + beta + phi) = 0 (N_gamma = 0 on a down-slope) makes these infinite; see below
        csc2_s = 1.0 / np.sin(beta + s_tot) ** 2
        csc2_p = 1.0 / np.sin(alpha_e + beta + phi) ** 2
        t1 = np.tan(alpha_e + beta)
        c2 = A2c / A2
        c4 = np.cos(beta + s_tot) / np.sin(beta + s_tot)
        dg_db = -t1 * t1 - c2 * c2 + cot_b * cot_b + c4 * c4
        dg_dp = -csc2_p + csc2_s
        dg_dd = csc2_s
        dg_dr = csc2_s
        dg_da = -1.0 - t1 * t1 - csc2_p
        db_dp_in = -(dg_dp + dg_dr * drho + dg_da * dalpha) / dg_db
        db_dd_in = -(dg_dd + dg_dr * drho) / dg_db
    # where the implicit-function derivative is not finite (a pole of d ln N_gamma / d beta), hold beta*
    # fixed: N_gamma is stationary in beta there (envelope theorem), so only N_c, N_a, N_q lose a term
    db_dp_in = np.where(np.isfinite(db_dp_in), db_dp_in, 0.0)
    db_dd_in = np.where(np.isfinite(db_dd_in), db_dd_in, 0.0)
    if depth is not None:  # the weight-force rule: implicit function theorem on h'(beta) = 0
        d2 = np.square(np.maximum(depth, 0.0))
        q = np.maximum(surcharge, 0.0)
        loaded = (d2 + q) > 0.0

        def partial(shift_b=0.0, shift_a=0.0, shift_r=0.0, shift_p=0.0, shift_d=0.0):
            up = weight_force_slope(beta + shift_b, alpha_e + shift_a, rho_e + shift_r, phi + shift_p,
                                    delta + shift_d, d2, q)
            down = weight_force_slope(beta - shift_b, alpha_e - shift_a, rho_e - shift_r, phi - shift_p,
                                      delta - shift_d, d2, q)
            return (up - down) / (2.0 * FD_STEP)

        with np.errstate(divide="ignore", invalid="ignore"):
            h_b = partial(shift_b=FD_STEP)
            h_r = partial(shift_r=FD_STEP)
            wf_dp = -(partial(shift_p=FD_STEP) + h_r * drho + partial(shift_a=FD_STEP) * dalpha) / h_b
            wf_dd = -(partial(shift_d=FD_STEP) + h_r * drho) / h_b
        wf_dp = np.where(np.isfinite(wf_dp), wf_dp, 0.0)
        wf_dd = np.where(np.isfinite(wf_dd), wf_dd, 0.0)
        db_dp_in = np.where(loaded, wf_dp, db_dp_in)  # an empty bucket: the paper's rule (above)
        db_dd_in = np.where(loaded, wf_dd, db_dd_in)
    # on a bound beta* moves with it: pi - s - eps2 (s = rho_eff + delta + phi) or pi/2 - alpha_eff
    interior, rho_limit, slope_limit = where == BETA_INTERIOR, where == BETA_AT_RHO_LIMIT, where == BETA_AT_SLOPE_LIMIT
    # (nested where: the same choice as np.select over the exclusive codes, at a fraction of its overhead)
    on_rho_limit = -(1.0 + drho)
    db_dp = np.where(interior, db_dp_in, np.where(rho_limit, on_rho_limit, np.where(slope_limit, -dalpha, 0.0)))
    db_dd = np.where(interior, db_dd_in, np.where(rho_limit, on_rho_limit, 0.0))
    return db_dp, db_dd


def factors(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS, derivatives: bool = False,
            depth=None, surcharge=None) -> Factors:
    """Bearing factors (eqs 10-13) at beta* (eq 14) for broadcast ``phi``, ``delta``.

    With ``derivatives=True`` also the total derivatives ``dN/dphi`` and
    ``dN/ddelta`` including ``d beta*/d(phi, delta)`` (implicit function
    theorem on ``d ln N_gamma / d beta = 0`` for interior roots; the moving
    bound for bound solutions) and the clamp of rho at its upper limit.
    The envelope theorem makes ``dN_gamma/dbeta = 0`` at interior roots, but
    N_c, N_a, N_q do depend on beta, so their beta terms are kept.

    With ``options.failure_angle == "min_weight_force"`` beta* minimises ``d^2 N_gamma + q N_q``
    (:func:`~wheelloader.estimator.failure_angle.optimal_beta_weight_force`), which needs the samples'
    ``depth`` [m] and ``surcharge`` ``q = r V_fill / w`` [m^2]; its derivatives in phi and delta come from
    the implicit function theorem on ``h'(beta) = 0`` for interior roots, with the partial derivatives of
    ``h'`` by central differences (the moving bound for bound solutions, as above).
    """
    clamps = clamp_details(alpha, rho, phi, delta, options)
    alpha_e, rho_e, rho_high = clamps.alpha, clamps.rho, clamps.rho_high
    flags_rho = clamps.rho_low | rho_high
    weight_rule = options.failure_angle == "min_weight_force"
    if weight_rule:
        if depth is None or surcharge is None:
            raise CalibrationError("factors: the min_weight_force failure angle needs depth and surcharge")
        beta, where = optimal_beta_weight_force(alpha_e, rho_e, phi, delta, depth, surcharge, options,
                                                return_where=True)
    else:
        beta, where = optimal_beta(alpha_e, rho_e, phi, delta, options, return_where=True)
    u = rho_e + delta + beta + phi
    S = np.sin(u)
    CU = np.cos(u)
    sin_b = np.sin(beta)
    cos_a = np.cos(alpha_e)
    A1 = np.cos(alpha_e + beta)
    A2 = np.sin(alpha_e + beta + phi)
    A2c = np.cos(alpha_e + beta + phi)
    D = 2.0 * cos_a * sin_b * S
    ng_raw = A1 * A2 / D  # eq 10
    ng = np.maximum(ng_raw, 0.0)
    cos_phi = np.cos(phi)
    nc = cos_phi / (sin_b * S)  # eq 11
    v = rho_e + beta + phi
    sin_r = np.sin(rho_e)
    na = -np.cos(v) / (sin_r * S)  # eq 12
    nq = A2 / S  # eq 13
    if not derivatives:
        return Factors(ng, nc, na, nq, flags_rho)

    cot_u = CU / S
    cot_b = np.cos(beta) / sin_b
    ng_pos = ng_raw > 0.0
    # partial derivatives (beta, phi, delta, rho held independent)
    dng_db = np.where(ng_pos, (-np.sin(alpha_e + beta) * A2 + A1 * A2c) / D - ng_raw * (cot_b + cot_u), 0.0)
    dng_dp = np.where(ng_pos, A1 * A2c / D - ng_raw * cot_u, 0.0)
    dng_dd = np.where(ng_pos, -ng_raw * cot_u, 0.0)
    dng_dr = dng_dd
    dnc_db = -nc * (cot_b + cot_u)
    dnc_dp = -np.sin(phi) / (sin_b * S) - nc * cot_u
    dnc_dd = -nc * cot_u
    dnc_dr = dnc_dd
    sv = np.sin(v) / (sin_r * S)
    dna_db = sv - na * cot_u
    dna_dp = dna_db
    dna_dd = -na * cot_u
    dna_dr = sv - na * cot_u - na * np.cos(rho_e) / sin_r
    dnq_db = A2c / S - nq * cot_u
    dnq_dp = dnq_db
    dnq_dd = -nq * cot_u
    dnq_dr = dnq_dd
    # partial derivatives in the slope alpha (N_c and N_a do not depend on it)
    dng_da = np.where(ng_pos, (-np.sin(alpha_e + beta) * A2 + A1 * A2c) / D + ng_raw * np.tan(alpha_e), 0.0)
    dnq_da = A2c / S
    # d alpha_eff / d phi = -1 where the slope is clamped at -phi (validity.alpha_lower_limit)
    dalpha = np.where(clamps.alpha_at_phi, -1.0, 0.0)
    # d rho_eff / d phi = d rho_eff / d delta = -1 where clamped at the upper limit
    drho = np.where(rho_high, -1.0, 0.0)
    db_dp, db_dd = _beta_star_derivatives(alpha_e, rho_e, beta, where, phi, delta, A2, A2c, cot_b, drho, dalpha,
                                          depth if weight_rule else None, surcharge)

    def total(dd_b, dd_x, dd_r, db_dx, dd_a=0.0, da_dx=0.0):
        return dd_x + dd_b * db_dx + dd_r * drho + dd_a * da_dx

    d_phi = (total(dng_db, dng_dp, dng_dr, db_dp, dng_da, dalpha), total(dnc_db, dnc_dp, dnc_dr, db_dp),
             total(dna_db, dna_dp, dna_dr, db_dp), total(dnq_db, dnq_dp, dnq_dr, db_dp, dnq_da, dalpha))
    d_delta = (total(dng_db, dng_dd, dng_dr, db_dd), total(dnc_db, dnc_dd, dnc_dr, db_dd),
               total(dna_db, dna_dd, dna_dr, db_dd), total(dnq_db, dnq_dd, dnq_dr, db_dd))
    return Factors(ng, nc, na, nq, flags_rho, d_phi, d_delta)
