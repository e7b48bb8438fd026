"""The force model arranged for fitting: batched basis, full model and analytic Jacobian.

For fixed ``(phi, delta)`` the failure angle beta* depends only on the sample
geometry (alpha, rho), so the FEE force of eq 1 is affine in
``(gamma, C, C_a)``::

    F = gamma * B_gamma + C * B_c + C_a * B_a + q0,
    B_gamma = d^2 w g N_gamma + r g V N_q        (W_load = gamma g V, eq 1)
    B_c     = w d N_c,   B_a = w d N_a,   q0 = r W_meas N_q (logged load only)

with ``r`` the surcharge ramp of :mod:`wheelloader.estimator.force_model`.
The blade forces (eqs 15-17) are then

    F_T = K w b d^n + F sin(delta) + C_a w L_t,     F_N = F cos(delta),

with ``K = k_c / b + k_phi`` (eq 15), the only identifiable Bekker
combination. So for fixed ``(phi, delta, n)`` the forces are linear in
``theta_lin = (gamma, C, C_a, K)``: the default calibration exploits this
(variable projection). The tension clamp ``F >= 0`` breaks linearity; the
full model here applies it exactly as :func:`~wheelloader.estimator.force_model.soil_forces`.

The fit parameter vector used throughout the estimator is the soil vector
:data:`FIT_NAMES` = ``(gamma, C, C_a, phi, delta, K, n)``
(:mod:`wheelloader.estimator.soil_vector`, also the planner's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import CalibrationError
from ..failure_angle import (
    BETA_AT_RHO_LIMIT,
    BETA_AT_SLOPE_LIMIT,
    BETA_INTERIOR,
    optimal_beta,
    optimal_beta_weight_force,
    weight_force_slope,
)
from ..force_model import DEFAULT_OPTIONS, GRAVITY, ModelOptions, carried_load_factors, slip_factor
from ..kinematics import ContactState
from ..machine import Bucket
from ..soil_vector import (
    LINEAR_INDEX,
    NONLINEAR_INDEX,
    SOIL_VECTOR_NAMES,
    soil_from_vector,
    soil_vector,
    split_sinkage,
    vector_bounds,
)
from ..validity import clamp_details

__all__ = ["FIT_NAMES", "LINEAR_INDEX", "MIN_SAMPLES", "NONLINEAR_INDEX", "Factors", "FitData", "factors", "fit_bounds",
           "fit_to_soil", "soil_to_fit", "split_sinkage"]

#: Names of the fit vector: the soil vector (:mod:`wheelloader.estimator.soil_vector`).
FIT_NAMES: tuple[str, ...] = SOIL_VECTOR_NAMES

#: Step [rad] of the central differences of the weight force's slope (least-weight-force failure angle).
FD_STEP = 1e-6

#: Smallest number of in-soil samples a calibration accepts.
MIN_SAMPLES = 12

#: The soil-vector converters under their calibration names.
fit_bounds = vector_bounds
soil_to_fit = soil_vector
fit_to_soil = soil_from_vector


# ----------------------------------------------------------------- factors
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


# ------------------------------------------------------------------- data
@dataclass(frozen=True, eq=False)
class FitData:
    """Measured forces and geometry of the in-soil samples of one cycle, ready for fitting.

    Attributes
    ----------
    index : numpy.ndarray
        Indices of the in-soil samples (depth > 0) in the cycle.
    depth, alpha, rho, blade_length, fill_volume : numpy.ndarray
        Geometry of those samples (SI).
    measured_load : numpy.ndarray or None
        Logged W_load [N] of those samples.
    y_t, y_n : numpy.ndarray
        Measured F_T, F_N [N] of those samples.
    width, edge_thickness : float
        Bucket width w and cutting-edge thickness b [m].
    options : ModelOptions
        Validity-domain options of the force model.
    weight : numpy.ndarray or None
        Weight of each sample's squared residual (None: every sample weighs 1). Set by
        :meth:`concat` for a forgetting factor over several cycles.
    cycle : numpy.ndarray or None
        Which cycle (0, 1, ...) each sample comes from, when the data join several cycles
        (:meth:`concat`); None for one cycle.
    carried : tuple of numpy.ndarray or None
        ``(c_T, c_N)`` of :func:`~wheelloader.estimator.force_model.carried_load_factors` per sample
        when ``options.carried_load`` is on (the opt-in carried-load term), else None; times the hand-over
        ``1 - ramp`` when ``options.carried_in_soil`` is False.
    carried_volume : numpy.ndarray or None
        The carried soil's volume per sample when it differs from ``fill_volume``
        (:attr:`~wheelloader.estimator.kinematics.ContactState.carried_volume`), else None.
    slip : numpy.ndarray or None
        :func:`~wheelloader.estimator.force_model.slip_factor` per sample when ``options.slip_friction``
        is on (it scales the blade friction and adhesion in F_T), else None.
    """

    index: np.ndarray
    depth: np.ndarray
    alpha: np.ndarray
    rho: np.ndarray
    blade_length: np.ndarray
    fill_volume: np.ndarray
    measured_load: np.ndarray | None
    y_t: np.ndarray
    y_n: np.ndarray
    width: float
    edge_thickness: float
    options: ModelOptions = DEFAULT_OPTIONS
    weight: np.ndarray | None = None
    cycle: np.ndarray | None = None
    carried: tuple[np.ndarray, np.ndarray] | None = None
    slip: np.ndarray | None = None
    carried_volume: np.ndarray | None = None

    @classmethod
    def concat(cls, parts: list[FitData], cycle_weights: list[float] | None = None) -> FitData:
        """Join the in-soil samples of several cycles into one data set (one soil fitted to all).

        Each part keeps its own geometry (depth to its own pile surface). ``index`` stays each
        cycle's own sample index; :attr:`cycle` says which cycle a sample comes from.

        Parameters
        ----------
        parts : list of FitData
            One per cycle, oldest first; same bucket (width, edge thickness) and options.
        cycle_weights : list of float, optional
            Weight of every squared residual of each cycle (e.g. a forgetting factor's powers);
            None: all 1 (then :attr:`weight` is None).
        """
        if not parts:
            raise CalibrationError("no cycles to join")
        first = parts[0]
        for k, part in enumerate(parts[1:], start=1):
            if (part.width, part.edge_thickness) != (first.width, first.edge_thickness):
                raise CalibrationError(f"cycle {k} has another bucket (width {part.width} m, edge thickness "
                                       f"{part.edge_thickness} m) than cycle 0 ({first.width} m, "
                                       f"{first.edge_thickness} m): one calibration needs one bucket")
            if part.options != first.options:
                raise CalibrationError(f"cycle {k} uses other force-model options than cycle 0")
        if any(p.measured_load is not None for p in parts) and not all(p.measured_load is not None for p in parts):
            raise CalibrationError("either every cycle or none must log W_load")
        cat = lambda name: np.concatenate([getattr(p, name) for p in parts])  # noqa: E731
        ml = None if first.measured_load is None else cat("measured_load")
        cycle = np.concatenate([np.full(len(p), k, dtype=int) for k, p in enumerate(parts)])
        weight = None
        if cycle_weights is not None:
            w = np.asarray(cycle_weights, dtype=float)
            if w.shape != (len(parts),) or not np.all(np.isfinite(w)) or np.any(w <= 0.0):
                raise CalibrationError(f"cycle weights must be {len(parts)} finite numbers > 0, got {cycle_weights!r}")
            if not np.all(w == 1.0):
                weight = w[cycle]
        carried = None
        if first.carried is not None:
            carried = (np.concatenate([p.carried[0] for p in parts]), np.concatenate([p.carried[1] for p in parts]))
        slip = None if first.slip is None else cat("slip")
        if any(p.carried_volume is not None for p in parts) and not all(p.carried_volume is not None for p in parts):
            raise CalibrationError("either every cycle or none must carry a payload volume")
        cv = None if first.carried_volume is None else cat("carried_volume")
        return cls(cat("index"), cat("depth"), cat("alpha"), cat("rho"), cat("blade_length"), cat("fill_volume"), ml,
                   cat("y_t"), cat("y_n"), first.width, first.edge_thickness, first.options, weight, cycle, carried,
                   slip, cv)

    @property
    def root_weight(self) -> np.ndarray | float:
        """``sqrt(weight)`` per sample, the factor of each residual row (1.0 when unweighted)."""
        return 1.0 if self.weight is None else np.sqrt(self.weight)

    @classmethod
    def from_state(cls, state: ContactState, tangential, normal, bucket: Bucket,
                   options: ModelOptions = DEFAULT_OPTIONS, min_samples: int = MIN_SAMPLES) -> FitData:
        """Select the in-soil samples of ``state`` and check the measured forces."""
        f_t = np.asarray(tangential, dtype=float)
        f_n = np.asarray(normal, dtype=float)
        n = len(state)
        for name, arr in (("tangential", f_t), ("normal", f_n)):
            if arr.shape != (n,):
                raise CalibrationError(f"measured {name} force must have one value per sample ({n}), "
                                       f"got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                bad = int(np.flatnonzero(~np.isfinite(arr))[0])
                raise CalibrationError(f"measured {name} force has NaN/inf values (first at sample {bad})")
        if n < min_samples:
            raise CalibrationError(f"too few samples: the cycle has {n}, a calibration needs at least {min_samples}")
        idx = np.flatnonzero(state.depth > 0.0)
        if idx.size == 0:
            raise CalibrationError("every sample is out of soil (depth <= 0): the tip never enters the pile; "
                                   "check the pile surface and the path coordinates")
        if idx.size < min_samples:
            raise CalibrationError(f"too few in-soil samples: {idx.size} of {n} have depth > 0, a calibration "
                                   f"needs at least {min_samples}")
        ml = None if state.measured_load is None else np.asarray(state.measured_load, float)[idx]
        carried = None
        if options.carried_load:
            acc = None if state.acceleration is None else state.acceleration[idx]
            carried = carried_load_factors(state.blade_angle[idx], acc)
            if not options.carried_in_soil:  # handed over from the surcharge (ModelOptions.carried_in_soil)
                hand_over = 1.0 - np.minimum(state.depth[idx] / options.contact_depth, 1.0)
                carried = (carried[0] * hand_over, carried[1] * hand_over)
        slip = None
        if options.slip_friction:
            vel = None if state.velocity is None else state.velocity[idx]
            slip = slip_factor(state.blade_angle[idx], vel, options.slip_speed)
        return cls(idx, state.depth[idx], state.alpha[idx], state.rho[idx], state.blade_length[idx],
                   state.fill_volume[idx], ml, f_t[idx], f_n[idx], bucket.width, bucket.edge_thickness, options,
                   carried=carried, slip=slip,
                   carried_volume=None if state.carried_volume is None else state.carried_volume[idx])

    def __len__(self) -> int:
        return int(self.index.size)

    def every(self, stride: int) -> FitData:
        """Every ``stride``-th sample (a uniform subsample in time; ``self`` for ``stride <= 1``)."""
        if stride <= 1:
            return self
        sl = slice(0, None, int(stride))
        ml = None if self.measured_load is None else self.measured_load[sl]
        return FitData(self.index[sl], self.depth[sl], self.alpha[sl], self.rho[sl], self.blade_length[sl],
                       self.fill_volume[sl], ml, self.y_t[sl], self.y_n[sl], self.width, self.edge_thickness,
                       self.options, None if self.weight is None else self.weight[sl],
                       None if self.cycle is None else self.cycle[sl],
                       None if self.carried is None else (self.carried[0][sl], self.carried[1][sl]),
                       None if self.slip is None else self.slip[sl],
                       None if self.carried_volume is None else self.carried_volume[sl])

    # Geometry-only arrays: they depend on the path and the pile, not on the soil, so each is computed once
    # per data set (not once per model evaluation of every start); the products keep the order of the
    # expressions they stand for, so the forces are the same to the last bit.
    @cached_property
    def ramp(self) -> np.ndarray:
        """Surcharge ramp ``min(d / contact_depth, 1)`` (force_model)."""
        return np.minimum(self.depth / self.options.contact_depth, 1.0)

    @cached_property
    def surcharge(self) -> np.ndarray:
        """``q = r V_fill / w`` [m^2] of the weight-force failure angle (failure_angle module docstring)."""
        return self.ramp * self.fill_volume / self.width

    @cached_property
    def log_depth(self) -> np.ndarray:
        """``ln d`` (the sinkage term's derivative in n)."""
        return np.log(self.depth)

    @cached_property
    def _basis_weights(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(d^2 w g, r g V_fill or r W_load, w d)``: the factors' weights in :meth:`fee_basis`."""
        d, w, r = self.depth, self.width, self.ramp
        surcharge = r * GRAVITY * self.fill_volume if self.measured_load is None else r * self.measured_load
        return d * d * w * GRAVITY, surcharge, w * d

    # ---------------------------------------------------------- basis
    def fee_basis(self, f: Factors):
        """``(B_gamma, B_c, B_a, q0)`` of the module docstring from :class:`Factors` (broadcast)."""
        weight, surcharge, wd = self._basis_weights
        if self.measured_load is None:
            b_gamma = weight * f.n_gamma + surcharge * f.n_q
            q0 = np.zeros_like(b_gamma)
        else:
            b_gamma = weight * f.n_gamma + np.zeros_like(f.n_q)
            q0 = surcharge * f.n_q
        return b_gamma, wd * f.n_c, wd * f.n_a, q0

    def fee_basis_derivative(self, dn: tuple[np.ndarray, ...]):
        """Derivative of :meth:`fee_basis` given derivatives of the four factors."""
        dng, dnc, dna, dnq = dn
        weight, surcharge, wd = self._basis_weights
        if self.measured_load is None:
            return weight * dng + surcharge * dnq, wd * dnc, wd * dna, np.zeros_like(dnq)
        return weight * dng, wd * dnc, wd * dna, surcharge * dnq

    def carried_basis(self):
        """The carried-load term as ``(b_T, b_N, o_T, o_N)``: F_T += gamma b_T + o_T, F_N += gamma b_N + o_N.

        ``W_load = gamma g V_fill`` gives the gamma columns, a logged ``W_load`` the offsets; None when the
        term is off (``options.carried_load`` False).
        """
        if self.carried is None:
            return None
        c_t, c_n = self.carried
        if self.carried_volume is not None or self.measured_load is None:
            load = GRAVITY * (self.fill_volume if self.carried_volume is None else self.carried_volume)
            zero = np.zeros_like(load)
            return load * c_t, load * c_n, zero, zero
        zero = np.zeros_like(c_t)
        return zero, zero, self.measured_load * c_t, self.measured_load * c_n

    def sinkage_basis(self, n):
        """``w b d^n`` for scalar or array ``n`` (array n: shape (len(n), samples))."""
        n = np.asarray(n, dtype=float)
        wb = self.width * self.edge_thickness
        if n.ndim == 0:
            return wb * np.power(self.depth, n)
        return wb * np.power(self.depth[None, :], n[:, None])

    # ----------------------------------------------------------- model
    def forces(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Model ``(F_T, F_N, tension)`` of the in-soil samples for fit vector ``p`` (same as soil_forces)."""
        gamma, c, ca, phi, delta, k, n = (float(v) for v in p)
        f = factors(self.alpha, self.rho, phi, delta, self.options, depth=self.depth, surcharge=self.surcharge)
        bg, bc, ba, q0 = self.fee_basis(f)
        fee = gamma * bg + c * bc + ca * ba + q0  # eq 1
        tension = fee < 0.0
        fee = np.maximum(fee, 0.0)
        sink = self.sinkage_basis(n)
        if self.slip is not None:  # opt-in slip-mobilised friction (force_model)
            f_t = k * sink + (fee * math.sin(delta) + ca * self.width * self.blade_length) * self.slip
        else:
            f_t = k * sink + fee * math.sin(delta) + ca * self.width * self.blade_length  # eqs 15-16
        f_n = fee * math.cos(delta)  # eq 17
        carried = self.carried_basis()
        if carried is not None:  # opt-in carried load (force_model)
            f_t = f_t + (gamma * carried[0] + carried[2])
            f_n = f_n + (gamma * carried[1] + carried[3])
        return f_t, f_n, tension

    def forces_and_jacobian(self, p: np.ndarray):
        """``(F_T, F_N, J_T, J_N)``: forces and their analytic Jacobians (samples x 7) w.r.t. :data:`FIT_NAMES`."""
        gamma, c, ca, phi, delta, k, n = (float(v) for v in p)
        f = factors(self.alpha, self.rho, phi, delta, self.options, derivatives=True, depth=self.depth,
                    surcharge=self.surcharge)
        bg, bc, ba, q0 = self.fee_basis(f)
        fee_raw = gamma * bg + c * bc + ca * ba + q0
        on = fee_raw >= 0.0
        fee = np.where(on, fee_raw, 0.0)
        dbg_p, dbc_p, dba_p, dq_p = self.fee_basis_derivative(f.d_phi)
        dbg_d, dbc_d, dba_d, dq_d = self.fee_basis_derivative(f.d_delta)
        dfee_phi = np.where(on, gamma * dbg_p + c * dbc_p + ca * dba_p + dq_p, 0.0)
        dfee_delta = np.where(on, gamma * dbg_d + c * dbc_d + ca * dba_d + dq_d, 0.0)
        sd, cd = math.sin(delta), math.cos(delta)
        sink = self.sinkage_basis(n)
        wl = self.width * self.blade_length
        if self.slip is not None:  # opt-in slip-mobilised friction: F_T's friction share scaled per sample
            sd = sd * self.slip
            wl = wl * self.slip
        f_t = k * sink + fee * sd + ca * wl
        f_n = fee * cd
        m = len(self)
        jt = np.empty((m, 7))
        jn = np.zeros((m, 7))
        bg_on, bc_on, ba_on = (np.where(on, v, 0.0) for v in (bg, bc, ba))
        jt[:, 0], jn[:, 0] = sd * bg_on, cd * bg_on
        jt[:, 1], jn[:, 1] = sd * bc_on, cd * bc_on
        jt[:, 2], jn[:, 2] = sd * ba_on + wl, cd * ba_on
        jt[:, 3], jn[:, 3] = sd * dfee_phi, cd * dfee_phi
        cd_t = cd if self.slip is None else cd * self.slip  # d(sin delta)/d delta in the F_T row
        jt[:, 4], jn[:, 4] = cd_t * fee + sd * dfee_delta, -math.sin(delta) * fee + cd * dfee_delta
        jt[:, 5] = sink
        jt[:, 6] = k * sink * self.log_depth
        carried = self.carried_basis()
        if carried is not None:  # opt-in carried load (force_model)
            f_t = f_t + (gamma * carried[0] + carried[2])
            f_n = f_n + (gamma * carried[1] + carried[3])
            jt[:, 0] += carried[0]
            jn[:, 0] += carried[1]
        return f_t, f_n, jt, jn
