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
from .fit_factors import Factors, factors

__all__ = ["FIT_NAMES", "LINEAR_INDEX", "MIN_SAMPLES", "NONLINEAR_INDEX", "Factors", "FitData", "factors", "fit_bounds",
           "fit_to_soil", "soil_to_fit", "split_sinkage"]

#: Names of the fit vector: the soil vector (:mod:`wheelloader.estimator.soil_vector`).
FIT_NAMES: tuple[str, ...] = SOIL_VECTOR_NAMES

#: Smallest number of in-soil samples a calibration accepts.
MIN_SAMPLES = 12

#: The soil-vector converters under their calibration names.
fit_bounds = vector_bounds
soil_to_fit = soil_vector
fit_to_soil = soil_from_vector


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
        n_gamma = f.n_gamma + self.options.wedge_offset if self.options.wedge_offset else f.n_gamma  # ModelOptions
        if self.measured_load is None:
            b_gamma = weight * n_gamma + surcharge * f.n_q
            q0 = np.zeros_like(b_gamma)
        else:
            b_gamma = weight * n_gamma + np.zeros_like(f.n_q)
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
