"""Bucket-pile kinematics: what the force model needs per sample.

From a bucket-tip path (x, z, blade angle per sample) and the pile surface
as it was when the cycle started, compute per sample:

* ``depth`` d [m]: penetration depth of the tip B, measured to the actual
  local surface: ``(z_s(x) - z) cos(alpha)``, which is the perpendicular
  distance for a planar slope and follows carved surfaces (the paper's
  dual-cycle correction, Section IV-B). Zero when the tip is above ground.
* ``alpha`` [rad]: local surface slope, the chord slope of the surface over
  ``x +- slope_window`` (continuous across kinks).
* ``rho`` [rad]: blade angle relative to the local surface,
  ``rho = alpha - blade_angle``.
* ``blade_length`` L_t [m]: blade length in soil, ``d / sin(rho)`` capped by
  the bucket floor length.
* ``fill_volume`` [m^3]: soil in the bucket, from carving the surface along
  the path (or as logged).

Sign conventions
----------------
x is horizontal, positive in the digging direction (into the pile); z is up.
``blade_angle`` is the angle of the blade direction, from its back edge A to
its tip B, above the +x axis, counter-clockwise positive: a bucket floor
tilted tip-down has a negative blade angle; curling the bucket raises it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .checks import check_range
from .errors import ParameterError
from .machine import Bucket
from .pile import CarveResult, Pile

GRAVITY = 9.81

#: Default half-width of the chord used for the local slope [m].
DEFAULT_SLOPE_WINDOW = 0.1
#: Blade angles below this (relative to the surface) count as "flat" when
#: computing the blade length in soil [rad].
_MIN_SIN_ANGLE = math.radians(10.0)
_MIN_SIN = math.sin(_MIN_SIN_ANGLE)  # the floor of |sin(rho)| in the blade length


@dataclass(frozen=True, eq=False)
class ContactState:
    """Per-sample geometry of the blade in the pile (see module docstring).

    Attributes
    ----------
    depth, rho, alpha, blade_length, fill_volume : numpy.ndarray
        As described in the module docstring; SI units.
    measured_load : numpy.ndarray or None
        Logged soil weight in the bucket W_load [N], when the log has it;
        otherwise the load is ``gamma * g * fill_volume``.
    carve : CarveResult or None
        The carving that produced ``fill_volume``, when it was computed.
    acceleration : numpy.ndarray or None
        Tip acceleration ``(a_x, a_z)`` per sample, shape ``(n, 2)`` [m/s^2], when known: the
        inertia of the carried soil (``ModelOptions.carried_load``); None counts as 0.
    velocity : numpy.ndarray or None
        Tip velocity ``(v_x, v_z)`` per sample, shape ``(n, 2)`` [m/s], when known (the opt-in
        ``ModelOptions.slip_friction``); None counts as standing still.
    carried_volume : numpy.ndarray or None
        The soil whose weight the opt-in carried-load term puts on the bucket [m^3] per sample, when it
        differs from the fill the surcharge sees (the payload model's kept soil,
        :func:`~wheelloader.estimator.payload.with_payload`); None: the load of :meth:`load_weight`.
    """

    depth: np.ndarray
    rho: np.ndarray
    alpha: np.ndarray
    blade_length: np.ndarray
    fill_volume: np.ndarray
    measured_load: np.ndarray | None = None
    carve: CarveResult | None = field(default=None, repr=False)
    acceleration: np.ndarray | None = field(default=None, repr=False)
    velocity: np.ndarray | None = field(default=None, repr=False)
    carried_volume: np.ndarray | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return int(self.depth.size)

    @property
    def in_soil(self) -> np.ndarray:
        """True where the tip is below the surface."""
        return self.depth > 0.0

    def load_weight(self, gamma: float) -> np.ndarray:
        """W_load [N]: the logged load, or ``gamma g V_fill`` (linear in gamma)."""
        if self.measured_load is not None:
            return self.measured_load
        return gamma * GRAVITY * self.fill_volume

    def carried_weight(self, gamma: float) -> np.ndarray:
        """The carried load's weight [N]: ``gamma g`` times :attr:`carried_volume`, else :meth:`load_weight`."""
        if self.carried_volume is None:
            return self.load_weight(gamma)
        return gamma * GRAVITY * self.carried_volume

    def subset(self, mask: np.ndarray) -> ContactState:
        """The samples where ``mask`` is true."""
        ml = None if self.measured_load is None else self.measured_load[mask]
        acc = None if self.acceleration is None else self.acceleration[mask]
        vel = None if self.velocity is None else self.velocity[mask]
        cv = None if self.carried_volume is None else self.carried_volume[mask]
        return ContactState(self.depth[mask], self.rho[mask], self.alpha[mask], self.blade_length[mask],
                            self.fill_volume[mask], ml, None, acc, vel, cv)

    @property
    def blade_angle(self) -> np.ndarray:
        """Blade direction above +x per sample [rad] (``alpha - rho``)."""
        return self.alpha - self.rho


def blade_length_in_soil(depth, rho, floor_length: float):
    """L_t = d / sin(rho), with sin(rho) floored at sin(10 deg), capped at the floor length [m]."""
    sin_rho = np.maximum(np.abs(np.sin(rho)), math.sin(_MIN_SIN_ANGLE))
    return np.minimum(np.maximum(depth, 0.0) / sin_rho, floor_length)


def contact_state(
    x: object,
    z: object,
    blade_angle: object,
    pile: Pile,
    bucket: Bucket,
    *,
    slope_window: float = DEFAULT_SLOPE_WINDOW,
    initial_fill: float = 0.0,
    fill_volume: object | None = None,
    measured_load: object | None = None,
    acceleration: object | None = None,
    velocity: object | None = None,
) -> ContactState:
    """Contact geometry along a tip path on a pile (vectorised).

    Parameters
    ----------
    x, z, blade_angle : array_like
        Tip path [m, m, rad], one value per sample.
    pile : Pile
        Surface at the start of the cycle; depth is measured to it.
    bucket : Bucket
        Bucket geometry (floor length, width, capacity).
    slope_window : float
        Half-width of the chord for the local slope [m].
    initial_fill : float
        Soil already in the bucket [m^3] when the fill is computed by carving.
    fill_volume : array_like, optional
        Logged bucket fill per sample [m^3]; if omitted it is computed by
        carving ``pile`` along the path.
    measured_load : array_like, optional
        Logged soil weight in the bucket per sample [N].
    acceleration : array_like, optional
        Tip acceleration per sample, shape ``(n, 2)`` [m/s^2] (e.g. from
        :meth:`~wheelloader.estimator.paths.BucketPath.acceleration`); used only by the
        opt-in carried-load term.
    velocity : array_like, optional
        Tip velocity per sample, shape ``(n, 2)`` [m/s]; used only by the opt-in slip-friction term.

    Returns
    -------
    ContactState
    """
    xs = np.asarray(x, dtype=float)
    zs = np.asarray(z, dtype=float)
    theta = np.asarray(blade_angle, dtype=float)
    if not (xs.ndim == zs.ndim == theta.ndim == 1 and xs.size == zs.size == theta.size):
        raise ParameterError("x, z and blade_angle must be 1-D arrays of equal length")
    if xs.size == 0:
        raise ParameterError("the path has no samples")
    for name, arr in (("x", xs), ("z", zs), ("blade_angle", theta)):
        if not np.all(np.isfinite(arr)):
            raise ParameterError(f"path {name} contains NaN or infinite values")
    check_range("slope_window", slope_window, 0.0, None, low_open=True)  # m
    alpha = pile.slope_angle(xs, slope_window)
    vertical = pile.surface_height(xs) - zs
    depth = np.maximum(vertical, 0.0) * np.cos(alpha)
    rho = alpha - theta
    blade_length = blade_length_in_soil(depth, rho, bucket.floor_length)
    carve = None
    if fill_volume is None:
        carve = pile.carve(xs, zs, bucket.width, bucket.capacity, initial_fill)
        fill = carve.fill_history
    else:
        fill = _optional_series("fill_volume", fill_volume, xs.size)
    load = None if measured_load is None else _optional_series("measured_load", measured_load, xs.size)
    acc, vel = (_optional_pairs(name, value, xs.size) for name, value in (("acceleration", acceleration),
                                                                          ("velocity", velocity)))
    return ContactState(depth, rho, alpha, blade_length, fill, load, carve, acc, vel)


def _optional_pairs(name: str, values: object | None, size: int) -> np.ndarray | None:
    if values is None:
        return None
    arr = np.asarray(values, dtype=float)
    if arr.shape != (size, 2) or not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} must be finite with shape ({size}, 2), got {arr.shape}")
    return arr


def contact_single(pile: Pile, x: float, z: float, blade_angle: float, floor_length: float,
                   slope_window: float = DEFAULT_SLOPE_WINDOW) -> tuple[float, float, float, float]:
    """Scalar fast path: ``(depth, rho, alpha, blade_length)`` for one tip pose (:func:`surface_contact`
    without the surface height)."""
    return surface_contact(pile, x, z, blade_angle, floor_length, slope_window)[:4]


def surface_contact(pile: Pile, x: float, z: float, blade_angle: float, floor_length: float,
                    slope_window: float = DEFAULT_SLOPE_WINDOW) -> tuple[float, float, float, float, float]:
    """Scalar contact of one tip pose: ``(depth, rho, alpha, blade_length, surface height at x)``.

    The surface arithmetic of :meth:`Pile.slope_angle` and :meth:`Pile.height_at` on the pile's node list;
    the surface height is what the env's cycle-end rule measures the tip's clearance to.
    """
    nodes, x0, sp = pile.nodes, pile.x0, pile.spacing
    last = len(nodes) - 1
    # node_height at x + window, x - window and x, inlined (the single env's hot path; the same arithmetic)
    u = (x + slope_window - x0) / sp
    if u <= 0.0:
        ahead = nodes[0]
    elif u >= last:
        ahead = nodes[last]
    else:
        i = int(u)
        a = nodes[i]
        ahead = a + (u - i) * (nodes[i + 1] - a)
    u = (x - slope_window - x0) / sp
    if u <= 0.0:
        behind = nodes[0]
    elif u >= last:
        behind = nodes[last]
    else:
        i = int(u)
        a = nodes[i]
        behind = a + (u - i) * (nodes[i + 1] - a)
    alpha = math.atan((ahead - behind) / (2.0 * slope_window))
    u = (x - x0) / sp
    if u <= 0.0:
        height = nodes[0]
    elif u >= last:
        height = nodes[last]
    else:
        i = int(u)
        a = nodes[i]
        height = a + (u - i) * (nodes[i + 1] - a)
    vertical = height - z
    if vertical <= 0.0:
        return 0.0, alpha - blade_angle, alpha, 0.0, height
    depth = vertical * math.cos(alpha)
    rho = alpha - blade_angle
    sin_rho = max(abs(math.sin(rho)), _MIN_SIN)
    return depth, rho, alpha, min(depth / sin_rho, floor_length), height


def _optional_series(name: str, values: object, size: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.shape != (size,):
        raise ParameterError(f"{name} must have one value per sample ({size}), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ParameterError(f"{name} must be finite and >= 0")
    return arr
