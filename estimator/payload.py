"""The payload as a state: the soil the bucket keeps, beyond the FEE's carved area.

The FEE books every m^3 a path removes as bucket fill, up to the nominal capacity. The continuum plant keeps
only part of it (0.51-0.70 of what a path removes in the project's 259 MPM cycles, ``../shared/model-notes.md``):
soil flows over the lip and the sides once a heap forms. This module models the kept soil as a state ``V`` [m^3]
that grows with the removed volume ``R`` times a retention fraction ``r`` and saturates smoothly at a heaped
capacity ``C = h * capacity``:

    V(R) = V_0 + u / (1 + (u / C_free)^p)^(1/p),   u = r R,   C_free = C - V_0,
    C = (h + g sin theta_exit) * capacity,

a smooth minimum of ``u`` and ``C_free`` (exponent ``p``; ``p -> inf`` gives the hard cap of
:meth:`~wheelloader.estimator.pile.Pile.carve`). ``V`` is monotone in ``R``, equals ``V_0 + r R`` for small cuts,
never exceeds ``C`` and is differentiable everywhere, so the planner can write it in CasADi
(:func:`kept_volume` works on NumPy arrays and on CasADi symbols alike).

The heaped capacity may depend on the curl: ``theta_exit`` is the blade angle (above +x, tip-down negative) as
the tip leaves the soil (the current one while it is in soil, held after it leaves: :func:`exit_angle_profile`),
and ``g`` (``PayloadOptions.curl_gain``, default 0: no dependence) how much more a bucket curled further at the
exit keeps. Measured on the project's MPM cycles (``docs/results/transfer.md``, "Kept fill"): at the same removed
volume the plant keeps more the more the bucket is curled as its tip leaves the soil (soil above the lip line
then has nothing left to hold it and runs off); the blade angle at the path's end, after the curl-out, does not
explain it. The kept soil's weight stays on the
bucket after the tip leaves the soil; the force model's opt-in carried-load term
(:class:`~wheelloader.estimator.validity.ModelOptions` ``carried_load=True``) resolves that weight (and its
inertia where the acceleration is known) in the blade frame.

"Fill" is this ``V`` wherever the payload model is selected: the predicted kept fill of a path is
``V`` at its end (:func:`kept_fill`), and :func:`payload_contact_state` gives the force model a contact state
whose ``carried_volume`` is ``V`` along the path (the surcharge keeps the FEE's carved fill; see
:func:`with_payload`).

The parameters ``(r, h, p, g)`` are calibrated from logs that carry the kept fill (the MPM plant's ``fill_volume``
column) by :func:`fit_payload`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .checks import check_range
from .cyclelog import CycleLog
from .errors import CalibrationError, ParameterError
from .kinematics import DEFAULT_SLOPE_WINDOW, GRAVITY, ContactState

__all__ = ["DEFAULT_FREE", "PAYLOAD_FIELDS", "PayloadOptions", "as_payload", "exit_angle_profile", "fit_payload",
           "kept_fill", "kept_volume", "kept_volume_float", "logged_kept", "payload_contact_state", "removed_volume",
           "with_kept_fill", "with_payload"]


@dataclass(frozen=True)
class PayloadOptions:
    """Parameters of the payload state.

    Attributes
    ----------
    retention : float
        ``r`` in (0, 1]: the share of the removed volume that enters the bucket before it heaps.
    heap_factor : float
        ``h`` > 0: the heaped capacity the bucket holds, as a multiple of its nominal ``capacity``.
    sharpness : float
        ``p`` in [1, 50]: how sharply the fill bends onto the heaped capacity (1 is gentle, 50 nearly a hard cap).
    curl_gain : float
        ``g`` in [-2, 2] (default 0): the heaped capacity is ``(h + g sin theta_exit)`` times the nominal one,
        ``theta_exit`` the blade angle as the tip leaves the soil [rad] (module docstring). It is floored at
        :data:`MIN_HEAP` of the nominal capacity.
    """

    retention: float = 1.0
    heap_factor: float = 1.0
    sharpness: float = 50.0
    curl_gain: float = 0.0

    def __post_init__(self) -> None:
        check_range("PayloadOptions.retention", self.retention, 0.0, 1.0, low_open=True)
        check_range("PayloadOptions.heap_factor", self.heap_factor, 0.0, 10.0, low_open=True)
        check_range("PayloadOptions.sharpness", self.sharpness, 1.0, 50.0)
        check_range("PayloadOptions.curl_gain", self.curl_gain, -2.0, 2.0)

    def to_dict(self) -> dict[str, float]:
        """Plain-JSON form (``curl_gain`` only where it is not 0, so older readers read the rest)."""
        out = {"retention": self.retention, "heap_factor": self.heap_factor, "sharpness": self.sharpness}
        if self.curl_gain != 0.0:
            out["curl_gain"] = self.curl_gain
        return out

    def heaped(self, capacity: float, exit_angle=0.0):
        """The heaped capacity ``(h + g sin theta_exit) capacity`` [m^3] (NumPy or CasADi ``exit_angle``)."""
        if self.curl_gain == 0.0:
            return self.heap_factor * capacity
        if hasattr(exit_angle, "fmax"):  # a CasADi expression: its own sin and fmax
            return (self.heap_factor + self.curl_gain * exit_angle.sin()).fmax(MIN_HEAP) * capacity
        return np.maximum(self.heap_factor + self.curl_gain * np.sin(exit_angle), MIN_HEAP) * capacity

    @classmethod
    def from_dict(cls, data: Mapping[str, float]) -> PayloadOptions:
        """From :meth:`to_dict`'s form (some keys may be left out); an unknown key raises ParameterError."""
        names = PAYLOAD_FIELDS
        unknown = sorted(str(k) for k in set(data) - set(names))
        if unknown:
            raise ParameterError(f"payload: unknown key(s) {unknown}; expected some of {list(names)}")
        return cls(**data)


def as_payload(value: PayloadOptions | Mapping[str, float] | None) -> PayloadOptions | None:
    """``None``, a :class:`PayloadOptions` or a mapping of its fields (:meth:`PayloadOptions.from_dict`)."""
    if value is None or isinstance(value, PayloadOptions):
        return value
    if isinstance(value, Mapping):
        return PayloadOptions.from_dict(value)
    raise ParameterError(f"payload must be a PayloadOptions, a dict or None, got {type(value).__name__}")


#: Floor of the heaped capacity's factor ``h + g sin theta_exit`` (a curl_gain that would make it vanish).
MIN_HEAP = 0.05


def exit_angle_profile(blade_angle: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Per sample, the blade angle the payload's heaped capacity sees: the current one while the tip is in soil
    (``depth > 0``) and before it first enters, the one at the last in-soil sample after it leaves [rad]."""
    angle = np.asarray(blade_angle, dtype=float)
    inside = np.asarray(depth) > 0.0
    idx = np.where(inside, np.arange(angle.size), -1)
    last = np.maximum.accumulate(idx)
    return np.where(inside | (last < 0), angle, angle[np.maximum(last, 0)])


def kept_volume(removed, capacity: float, options: PayloadOptions, initial: float = 0.0, exit_angle=0.0):
    """Kept soil ``V`` [m^3] for a removed volume ``removed`` [m^3] (module docstring).

    Works elementwise on NumPy arrays and on CasADi ``SX``/``MX`` expressions (only ``+ * / **`` and ``fmax``
    through ``numpy``'s dispatch are used).

    Parameters
    ----------
    removed : array_like or casadi expression
        Cumulative volume removed from the pile since the cycle started [m^3], >= 0.
    capacity : float
        The bucket's nominal capacity [m^3].
    options : PayloadOptions
        ``(r, h, p)``.
    initial : float
        Soil already in the bucket when the cycle starts [m^3].
    exit_angle : float, array_like or casadi expression
        The blade angle as the tip leaves the soil [rad] (:func:`exit_angle_profile` per sample); used only
        where ``options.curl_gain`` is not 0.
    """
    free = options.heaped(capacity, exit_angle) - initial
    if isinstance(free, np.ndarray) and free.ndim:
        free = np.maximum(free, 1e-12)  # (a bucket holding its heap at the start keeps nothing more)
    elif np.isscalar(free) and free <= 0.0:
        return initial + 0.0 * removed
    u = options.retention * removed
    if isinstance(u, np.ndarray) or np.isscalar(u):
        u = np.maximum(u, 0.0)
    p = options.sharpness
    return initial + u / (1.0 + (u / free) ** p) ** (1.0 / p)


def kept_volume_float(removed: float, capacity: float, options: PayloadOptions, initial: float = 0.0,
                      exit_angle: float = 0.0) -> float:
    """:func:`kept_volume` of one Python float (the env's step: no NumPy scalars), the same formula."""
    if options.curl_gain == 0.0:
        free = options.heap_factor * capacity - initial
    else:
        free = max(options.heap_factor + options.curl_gain * math.sin(exit_angle), MIN_HEAP) * capacity - initial
    if free <= 0.0:
        return initial
    u = options.retention * removed
    if u <= 0.0:
        return initial
    p = options.sharpness
    return initial + u / (1.0 + (u / free) ** p) ** (1.0 / p)


def removed_volume(kept: float, capacity: float, options: PayloadOptions, initial: float = 0.0,
                   exit_angle: float = 0.0) -> float:
    """The removed volume [m^3] whose kept soil is ``kept`` (:func:`kept_volume` inverted, in closed form:
    ``u = v / (1 - (v / C_free)^p)^(1/p)``, ``v = kept - V_0``, ``R = u / r``); inf at or above the heaped
    capacity."""
    free = float(options.heaped(capacity, exit_angle)) - initial
    v = kept - initial
    if v <= 0.0:
        return 0.0
    if free <= 0.0 or v >= free:
        return math.inf
    p = options.sharpness
    return v / (1.0 - (v / free) ** p) ** (1.0 / p) / options.retention


def kept_fill(state: ContactState, capacity: float, options: PayloadOptions, initial: float = 0.0,
              blade_angle: np.ndarray | None = None) -> float:
    """The kept fill [m^3] at the end of a path whose contact state carries its carving (``blade_angle``: the
    path's, per sample [rad]; needed where ``options.curl_gain`` is not 0)."""
    if state.carve is None:
        raise ParameterError("kept_fill needs a contact state computed by carving (fill='model')")
    angle = _exit_angles(state, options, blade_angle)
    return float(kept_volume(state.carve.removed_history[-1], capacity, options, initial,
                             angle[-1] if isinstance(angle, np.ndarray) else 0.0))


def _exit_angles(state: ContactState, options: PayloadOptions, blade_angle: np.ndarray | None):
    """:func:`exit_angle_profile` of a state's path, or 0 where the payload has no curl dependence."""
    if options.curl_gain == 0.0:
        return 0.0
    if blade_angle is None:
        raise ParameterError("a payload with a curl_gain needs the path's blade angle (blade_angle=)")
    angle = np.asarray(blade_angle, dtype=float)
    if angle.shape != state.depth.shape:
        raise ParameterError(f"blade_angle has {angle.size} samples, the contact state {state.depth.size}")
    return exit_angle_profile(angle, state.depth)


def payload_contact_state(log: CycleLog, options: PayloadOptions,
                          slope_window: float = DEFAULT_SLOPE_WINDOW) -> ContactState:
    """The log's contact state under the ``"fee-payload"`` force model (:func:`with_payload`).

    The carving follows the log's pile and path (``fill='model'``): the surcharge sees the carved fill, the
    carried load the payload's kept soil. A logged load or fill is not used: this is what the model predicts
    for the path.
    """
    return with_payload(log.contact_state(slope_window=slope_window, fill="model"), log.bucket.capacity, options,
                        blade_angle=log.path.blade_angle)


def with_payload(state: ContactState, capacity: float, options: PayloadOptions,
                 initial: float = 0.0, blade_angle: np.ndarray | None = None) -> ContactState:
    """``state`` (computed by carving) with the payload's kept soil as its carried volume (``blade_angle``: the
    path's, per sample [rad]; needed where ``options.curl_gain`` is not 0).

    The surcharge ``W_load N_q`` keeps the FEE's carved fill; the carried-load term
    (:attr:`~wheelloader.estimator.validity.ModelOptions.carried_in_soil` False) puts the kept soil's weight on
    the bucket as the tip leaves the soil. Measured on ``data/mpm`` (``docs/guide/force_models.md``): the kept
    soil as the surcharge's fill, or its weight added in soil, made unseen paths worse in soil.
    """
    if state.carve is None:
        raise ParameterError("the payload model needs the carved volume (a contact state computed by carving)")
    kept = kept_volume(state.carve.removed_history, capacity, options, initial,
                       _exit_angles(state, options, blade_angle))
    return replace(state, carried_volume=np.asarray(kept, dtype=float), measured_load=None)


def with_kept_fill(state: ContactState, capacity: float, options: PayloadOptions,
                   initial: float = 0.0, blade_angle: np.ndarray | None = None) -> ContactState:
    """``state`` (computed by carving) with the payload's kept soil as its fill and no logged load
    (``blade_angle`` as :func:`with_payload`)."""
    if state.carve is None:
        raise ParameterError("the payload model needs the carved volume (a contact state computed by carving)")
    fill = kept_volume(state.carve.removed_history, capacity, options, initial,
                       _exit_angles(state, options, blade_angle))
    return replace(state, fill_volume=np.asarray(fill, dtype=float), measured_load=None)


#: The parameters :func:`fit_payload` may fit, in ``PayloadOptions`` order, with their bounds.
PAYLOAD_FIELDS: tuple[str, ...] = ("retention", "heap_factor", "sharpness", "curl_gain")
#: What :func:`fit_payload` fits unless told otherwise (the curl dependence is opt-in).
DEFAULT_FREE: tuple[str, ...] = ("retention", "heap_factor", "sharpness")
_BOUNDS = {"retention": (1e-3, 1.0), "heap_factor": (1e-2, 10.0), "sharpness": (1.0, 50.0), "curl_gain": (-2.0, 2.0)}
#: Where :func:`fit_payload` compares the model with the logged kept fill.
FIT_SAMPLES = ("path", "end")


def logged_kept(log: CycleLog, density: float | None = None) -> np.ndarray | None:
    """The kept soil a log carries [m^3]: its ``fill_volume``, else its logged load ``W_load / (gamma g)`` (with
    ``density`` [kg/m^3], else the log's ``metadata["true_soil"]["gamma"]``), else None.

    Raises
    ------
    CalibrationError
        A log with a load but no density.
    """
    if log.fill_volume is not None:
        return log.fill_volume
    if log.measured_load is None:
        return None
    if density is None:
        density = (log.metadata.get("true_soil") or {}).get("gamma")
    if density is None:
        raise CalibrationError(f"log {log.path.name!r} has a logged load (W_load) but no fill: pass its soil's "
                               "density (density=) to turn the load into the kept volume")
    return np.asarray(log.measured_load, dtype=float) / (check_range("density", density, 0.0, low_open=True)
                                                         * GRAVITY)


def fit_payload(logs: Sequence[CycleLog], *, slope_window: float = DEFAULT_SLOPE_WINDOW,
                free: Sequence[str] = DEFAULT_FREE, initial: PayloadOptions | None = None,
                density: float | None = None, samples: str = "path",
                max_kept_ratio: float | None = None) -> PayloadOptions:
    """Calibrate the payload ``(r, h, p, g)`` to logs that carry the kept fill or the load.

    Least squares on the relative error of the kept fill: with ``samples="path"`` (default) along each path,
    every sample where the log's fill is above 2 % of the capacity weighted alike (so a cycle's end and its rise
    both count); with ``samples="end"`` at each path's end only (what a cycle delivers). A log's kept fill is
    its ``fill_volume`` (the plant's kept soil; the env's fill under ``"fee-payload"``), else its logged load
    over ``gamma g`` (:func:`logged_kept`); logs with neither are skipped.

    Parameters
    ----------
    logs : sequence of CycleLog
        The cycles.
    slope_window : float
        As :meth:`CycleLog.contact_state` (the carving of each path gives the removed volume).
    free : sequence of str
        The parameters fitted (names of :data:`PAYLOAD_FIELDS`; default :data:`DEFAULT_FREE`); the others stay
        at ``initial``'s. A cycle that does not fill the bucket to its heap identifies the retention only:
        ``free=("retention",)``. ``"curl_gain"`` needs paths whose blade angle at the exit from the soil varies.
    initial : PayloadOptions, optional
        The start of the fit and the values of the held parameters (default ``(0.9, 0.7, 2.0, 0)``).
    density : float, optional
        Soil density [kg/m^3] of logs that carry a load but no fill (default: each log's true soil).
    samples : {"path", "end"}
        Where the model is compared with the log (above).
    max_kept_ratio : float, optional
        Skip a log whose kept fill at its end exceeds this share of the volume its carving removed: its logged
        start pile is not the surface the plant dug (on the project's MPM loops, a carved face that slumped into
        the bucket while the soil settled keeps up to 1.6 times what the path removed). Default: keep every log.

    Raises
    ------
    CalibrationError
        If no log carries a fill or a load.
    """
    from scipy.optimize import least_squares

    unknown = sorted(set(free) - set(PAYLOAD_FIELDS))
    if unknown or not free:
        raise ParameterError(f"fit_payload: free must name some of {list(PAYLOAD_FIELDS)}, got {list(free)}")
    if samples not in FIT_SAMPLES:
        raise ParameterError(f"fit_payload: samples must be one of {list(FIT_SAMPLES)}, got {samples!r}")
    if max_kept_ratio is not None:
        check_range("max_kept_ratio", max_kept_ratio, 0.0, None, low_open=True)
    start = initial or PayloadOptions(0.9, 0.7, 2.0)
    removed, kept, caps, angles = [], [], [], []
    for log in logs:
        logged = logged_kept(log, density)
        if logged is None:
            continue
        state = log.contact_state(slope_window=slope_window, fill="model")
        history = state.carve.removed_history
        if max_kept_ratio is not None and logged[-1] > max_kept_ratio * history[-1]:
            continue
        mask = logged > 0.02 * log.bucket.capacity
        if samples == "end":
            mask = mask & (np.arange(mask.size) == mask.size - 1)
        removed.append(history[mask])
        kept.append(logged[mask])
        caps.append(np.full(int(mask.sum()), log.bucket.capacity))
        angles.append(exit_angle_profile(log.path.blade_angle, state.depth)[mask])
    if not removed or sum(r.size for r in removed) == 0:
        raise CalibrationError("fit_payload needs logs with a logged fill_volume or load (the plant's kept soil)")
    r_all, k_all, c_all, a_all = (np.concatenate(v) for v in (removed, kept, caps, angles))
    names = [name for name in PAYLOAD_FIELDS if name in free]

    def options(theta: np.ndarray) -> PayloadOptions:
        return replace(start, **{name: float(t) for name, t in zip(names, theta, strict=True)})

    def residual(theta: np.ndarray) -> np.ndarray:
        opts = options(theta)
        heaped = np.maximum(opts.heap_factor + opts.curl_gain * np.sin(a_all), MIN_HEAP) * c_all
        u = opts.retention * r_all
        model = u / (1.0 + (u / heaped) ** opts.sharpness) ** (1.0 / opts.sharpness)
        return (model - k_all) / k_all

    scale = {"retention": 0.1, "heap_factor": 0.1, "sharpness": 1.0, "curl_gain": 0.1}
    fit = least_squares(residual, x0=[getattr(start, n) for n in names],
                        bounds=([_BOUNDS[n][0] for n in names], [_BOUNDS[n][1] for n in names]),
                        x_scale=[scale[n] for n in names])
    return options(fit.x)
