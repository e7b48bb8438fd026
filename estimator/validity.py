"""Validity domain of the modified FEE: numerical options, flags and the angle clamps.

The FEE's soil wedge exists only for some geometries (paper Section II-A and
eq 14). Outside them the force model clamps the angles into the domain and
flags the sample (README, "Validity domain"):

* ``rho`` is clamped to ``[rho_min, pi - eps1 - eps2 - delta - phi]``: below
  ``rho_min`` (10 deg, paper Section II-A) the blade is nearly parallel to
  the surface and the wedge vanishes; above the upper limit the feasible
  range of beta in eq 14 is empty (:data:`FLAG_RHO_LOW`, :data:`FLAG_RHO_HIGH`).
* ``alpha`` is clamped to ``[-min(phi - slope_margin, alpha_max), alpha_max]``
  (:data:`FLAG_ALPHA_CLAMPED`). The upper limit (60 deg) is a modelling
  choice. The lower limit follows the friction angle, because beta* (eq 14)
  is not defined on steeper down-slopes:

  - for ``alpha < -phi`` the factor ``sin(alpha + beta + phi)`` of N_gamma
    and N_q (eqs 10, 13) is negative for every ``beta < -alpha - phi`` (the
    wedge's weight would pull the blade), N_gamma has two zeros and is not
    unimodal on what is left of the branch, and its minimiser jumps between
    them: the forces jumped by up to 0.8 MN there;
  - at ``alpha = -phi`` and ``rho + delta + phi = pi/2 - phi`` N_gamma does not
    depend on beta at all, and near that point beta* sweeps the whole branch
    within a fraction of a degree (a jump in practice). ``slope_margin`` (5 deg,
    like the margins eps1, eps2 of eq 14) keeps the domain that far away.

  A soil surface steeper than its friction angle does not stand (angle of
  repose). For soils with ``phi < slope_margin`` the limit is an up-slope: flat
  ground counts as a slope of ``slope_margin - phi`` and is flagged.

Every clamp is continuous, so forces stay continuous along smooth paths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .checks import check_choice, check_range
from .errors import ParameterError

#: Flag bit: the tip is out of soil (depth <= 0), every force is zero.
FLAG_OUT_OF_SOIL = 1
#: Flag bit: rho below rho_min, clamped.
FLAG_RHO_LOW = 2
#: Flag bit: rho + delta + phi above pi - eps1 - eps2, clamped (no valid beta).
FLAG_RHO_HIGH = 4
#: Flag bit: alpha outside ``[-min(phi - slope_margin, alpha_max), alpha_max]``, clamped.
FLAG_ALPHA_CLAMPED = 8
#: Flag bit: eq 1 negative (adhesion would pull the blade), clamped to 0.
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
    slope_margin : float
        Down-slopes are limited to ``alpha >= -(phi - slope_margin)`` [rad]; default 5 deg
        (module docstring).
    contact_depth : float
        Depth over which the surcharge ``W_load N_q`` ramps in [m]; default 0.02 m.
    carried_load : bool
        Opt-in term beyond the paper (default False, the paper's model): the soil already in the
        bucket pushes on it with its weight and, when the tip's acceleration is known, its inertia,
        ``m (g - a)`` with ``m = W_load / g``, resolved in the blade frame and added to F_T and F_N
        in and out of soil (:func:`~wheelloader.estimator.force_model.carried_load_factors`). The
        env and the planner use it through their ``force_model="fee-payload"`` (with
        ``carried_in_soil=False``), not through these options (:attr:`extra_terms` names the
        opt-in terms that are on).
    carried_in_soil : bool
        With ``carried_load``: True (default) puts the carried load on in and out of soil; False ramps it
        in as the tip leaves the soil, by ``1 - min(d / contact_depth, 1)`` (the complement of the surcharge
        ramp, so the two terms hand over continuously): in soil the FEE's surcharge ``W_load N_q`` already
        stands for the soil in the bucket, and adding its weight again made unseen paths worse (measured in
        ``docs/guide/force_models.md``). The ``"fee-payload"`` force model uses False.
    slip_friction : bool
        Opt-in term beyond the paper (default False): the blade friction and adhesion (the F_T
        share ``F sin(delta) + C_a w L_t`` of eq 16) are mobilised by the soil slipping along the
        blade, so they are scaled by ``m = (max(v_a, 0) + v_0) / (|v| + v_0)``, the share of the
        tip's motion along the blade (``v_a`` its component along the blade direction, ``v_0 =
        slip_speed``): 1 when the blade advances along itself or stands still (the paper's
        model), towards 0 when it moves along its normal (lifting the load)
        (:func:`~wheelloader.estimator.force_model.slip_factor`). Not in the env or the planner either.
    slip_speed : float
        ``v_0`` of ``slip_friction`` [m/s]; default 0.05 m/s.
    failure_angle : {"min_n_gamma", "min_weight_force"}
        How beta* is chosen: ``"min_n_gamma"`` (default) minimises N_gamma as the paper does (eq 14);
        ``"min_weight_force"`` (opt-in, beyond the paper) minimises the force of the soil's weight,
        wedge and surcharge, ``d^2 N_gamma + q N_q`` with ``q = r V_fill / w``
        (:mod:`~wheelloader.estimator.failure_angle`). The planner's CasADi model does not implement it
        (it is named in :attr:`extra_terms`).
    wedge_offset : float
        Opt-in term beyond the paper (default 0, the paper's model): ``k >= 0`` added to the wedge factor
        N_gamma of eq 10 after its clamp at 0, so eq 1's weight term is ``gamma g w d^2 (N_gamma + k)``: a
        depth-squared share of the soil's weight that does not depend on phi, resolved like the FEE force
        (``sin(delta)``, ``cos(delta)``, eqs 16-17). Fitted to the continuum's paths, the FEE alone makes phi
        and a fake cohesion carry the depth scaling (phi 15-30 deg below the continuum's); with ``k`` a term of
        fixed shape carries it, which transfers better to other depths, though the fitted phi is no more
        physical (``docs/results/model_form.md``). The ``"fee-payload-depth"`` force model sets it
        (:data:`~wheelloader.estimator.DEFAULT_WEDGE_OFFSET`).
    """

    eps1: float = math.radians(5.0)
    eps2: float = math.radians(5.0)
    rho_min: float = math.radians(10.0)
    alpha_max: float = math.radians(60.0)
    contact_depth: float = 0.02
    slope_margin: float = math.radians(5.0)
    carried_load: bool = False
    carried_in_soil: bool = True
    slip_friction: bool = False
    slip_speed: float = 0.05
    failure_angle: str = "min_n_gamma"
    wedge_offset: float = 0.0

    @property
    def extra_terms(self) -> tuple[str, ...]:
        """Names of the opt-in terms beyond the paper's model that are on (empty: the paper's model)."""
        names = tuple(name for name in ("carried_load", "slip_friction") if getattr(self, name))
        names += ("failure_angle",) if self.failure_angle != "min_n_gamma" else ()
        return names + (("wedge_offset",) if self.wedge_offset != 0.0 else ())

    def __post_init__(self) -> None:
        check_choice("ModelOptions.failure_angle", self.failure_angle, ("min_n_gamma", "min_weight_force"))
        for name in ("carried_load", "carried_in_soil", "slip_friction"):
            if not isinstance(getattr(self, name), bool):
                raise ParameterError(f"ModelOptions.{name} must be True or False, got {getattr(self, name)!r}")
        for name in ("eps1", "eps2", "rho_min", "alpha_max", "contact_depth", "slope_margin", "slip_speed"):
            check_range(f"ModelOptions.{name}", getattr(self, name), 0.0, None, low_open=True)
        check_range("ModelOptions.wedge_offset", self.wedge_offset, 0.0, 100.0)
        if self.eps1 + self.eps2 + self.rho_min >= math.pi / 2 or self.alpha_max >= math.pi / 2 - self.eps1:
            raise ParameterError("ModelOptions: eps1 + eps2 + rho_min must be < 90 deg and alpha_max < 90 deg - eps1")


DEFAULT_OPTIONS = ModelOptions()


class AngleClamps(NamedTuple):
    """Clamped angles and where each clamp acted (boolean arrays, broadcast shape)."""

    alpha: np.ndarray
    rho: np.ndarray
    rho_low: np.ndarray
    rho_high: np.ndarray
    alpha_high: np.ndarray
    alpha_low: np.ndarray
    alpha_at_phi: np.ndarray
    """Where alpha was raised to ``slope_margin - phi`` (so d alpha_eff / d phi = -1 there)."""

    @property
    def flags(self) -> np.ndarray:
        """Bitwise OR of the ``FLAG_*`` of the clamps that acted."""
        flags = np.where(self.rho_low, FLAG_RHO_LOW, 0) | np.where(self.rho_high, FLAG_RHO_HIGH, 0)
        flags |= np.where(self.alpha_high | self.alpha_low, FLAG_ALPHA_CLAMPED, 0)
        return flags.astype(np.int64)


def rho_upper_limit(phi, delta, options: ModelOptions = DEFAULT_OPTIONS):
    """Largest blade angle of the domain, ``pi - eps1 - eps2 - delta - phi`` [rad]."""
    return math.pi - options.eps1 - options.eps2 - delta - phi


def alpha_lower_limit(phi, options: ModelOptions = DEFAULT_OPTIONS, minimum=np.minimum):
    """Steepest down-slope of the domain, ``-min(phi - slope_margin, alpha_max)`` [rad] (module docstring).

    ``minimum`` is the array library's element-wise minimum (the CasADi model passes a smooth one).
    """
    return -minimum(phi - options.slope_margin, options.alpha_max)


def clamp_details(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS) -> AngleClamps:
    """Clamp (alpha, rho) into the validity domain and say where each clamp acted (all inputs broadcast)."""
    alpha = np.asarray(alpha, dtype=float)
    rho = np.asarray(rho, dtype=float)
    rho_hi = rho_upper_limit(phi, delta, options)
    alpha_lo = alpha_lower_limit(phi, options)
    rho_low = rho < options.rho_min
    rho_high = ~rho_low & (rho > rho_hi)
    alpha_high = alpha > options.alpha_max
    alpha_low = alpha < alpha_lo
    alpha_at_phi = alpha_low & (np.asarray(phi) - options.slope_margin < options.alpha_max)
    rho_eff = np.where(rho_low, options.rho_min, np.where(rho_high, rho_hi, rho))
    alpha_eff = np.where(alpha_high, options.alpha_max, np.where(alpha_low, alpha_lo, alpha))
    return AngleClamps(alpha_eff, rho_eff, rho_low, rho_high, alpha_high, alpha_low, alpha_at_phi)


def clamp_angles(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS):
    """Clamp (alpha, rho) into the validity domain; return ``(alpha_eff, rho_eff, flags)``.

    The same limits as :func:`clamp_details` (:func:`rho_upper_limit`, :func:`alpha_lower_limit`), in the
    fewest array operations (the force model's hot path).
    """
    alpha = np.asarray(alpha, dtype=float)
    rho = np.asarray(rho, dtype=float)
    rho_hi = rho_upper_limit(phi, delta, options)
    alpha_lo = alpha_lower_limit(phi, options)
    flags = np.where(rho < options.rho_min, FLAG_RHO_LOW, 0)
    flags |= np.where(rho > rho_hi, FLAG_RHO_HIGH, 0)
    flags |= np.where((alpha > options.alpha_max) | (alpha < alpha_lo), FLAG_ALPHA_CLAMPED, 0)
    # np.clip as maximum then minimum: the same values, without np.clip's Python-level wrapper
    return (np.minimum(np.maximum(alpha, alpha_lo), options.alpha_max),
            np.minimum(np.maximum(rho, options.rho_min), rho_hi), flags.astype(np.int64))
