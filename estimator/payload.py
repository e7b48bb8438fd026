"""The payload as a state: the soil the bucket keeps, beyond the FEE's carved area.

The FEE books every m^3 a path removes as bucket fill, up to the nominal capacity. The continuum plant keeps
only part of it (0.51-0.70 of what a path removes in the project's 259 MPM cycles, ``../shared/model-notes.md``):
soil flows over the lip and the sides once a heap forms. This module models the kept soil as a state ``V`` [m^3]
that grows with the removed volume ``R`` times a retention fraction ``r`` and saturates smoothly at a heaped
capacity ``C = h * capacity``:

    V(R) = V_0 + u / (1 + (u / C_free)^p)^(1/p),   u = r R,   C_free = C - V_0,

a smooth minimum of ``u`` and ``C_free`` (exponent ``p``; ``p -> inf`` gives the hard cap of
:meth:`~wheelloader.estimator.pile.Pile.carve`). ``V`` is monotone in ``R``, equals ``V_0 + r R`` for small cuts,
never exceeds ``C`` and is differentiable everywhere, so the planner can write it in CasADi
(:func:`kept_volume` works on NumPy arrays and on CasADi symbols alike). The kept soil's weight stays on the
bucket after the tip leaves the soil; the force model's opt-in carried-load term
(:class:`~wheelloader.estimator.validity.ModelOptions` ``carried_load=True``) resolves that weight (and its
inertia where the acceleration is known) in the blade frame.

"Fill" is this ``V`` wherever the payload model is selected: the predicted kept fill of a path is
``V`` at its end (:func:`kept_fill`), and :func:`payload_contact_state` gives the force model a contact state
whose ``carried_volume`` is ``V`` along the path (the surcharge keeps the FEE's carved fill; see
:func:`with_payload`).

The parameters ``(r, h, p)`` are calibrated from logs that carry the kept fill (the MPM plant's ``fill_volume``
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

__all__ = ["PAYLOAD_FIELDS", "PayloadOptions", "as_payload", "fit_payload", "kept_fill", "kept_volume",
           "kept_volume_float", "logged_kept", "payload_contact_state", "removed_volume", "with_kept_fill",
           "with_payload"]


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
    """

    retention: float = 1.0
    heap_factor: float = 1.0
    sharpness: float = 50.0

    def __post_init__(self) -> None:
        check_range("PayloadOptions.retention", self.retention, 0.0, 1.0, low_open=True)
        check_range("PayloadOptions.heap_factor", self.heap_factor, 0.0, 10.0, low_open=True)
        check_range("PayloadOptions.sharpness", self.sharpness, 1.0, 50.0)

    def to_dict(self) -> dict[str, float]:
        """Plain-JSON form."""
        return {"retention": self.retention, "heap_factor": self.heap_factor, "sharpness": self.sharpness}

    @classmethod
    def from_dict(cls, data: Mapping[str, float]) -> PayloadOptions:
        """From :meth:`to_dict`'s form (some keys may be left out); an unknown key raises ParameterError."""
        names = ("retention", "heap_factor", "sharpness")
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


def kept_volume(removed, capacity: float, options: PayloadOptions, initial: float = 0.0):
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
    """
    heaped = options.heap_factor * capacity
    free = heaped - initial
    if free <= 0.0:
        return initial + 0.0 * removed
    u = options.retention * removed
    if isinstance(u, np.ndarray) or np.isscalar(u):
        u = np.maximum(u, 0.0)
    p = options.sharpness
    return initial + u / (1.0 + (u / free) ** p) ** (1.0 / p)


def kept_volume_float(removed: float, capacity: float, options: PayloadOptions, initial: float = 0.0) -> float:
    """:func:`kept_volume` of one Python float (the env's step: no NumPy scalars), the same formula."""
    free = options.heap_factor * capacity - initial
    if free <= 0.0:
        return initial
    u = options.retention * removed
    if u <= 0.0:
        return initial
    p = options.sharpness
    return initial + u / (1.0 + (u / free) ** p) ** (1.0 / p)


def removed_volume(kept: float, capacity: float, options: PayloadOptions, initial: float = 0.0) -> float:
    """The removed volume [m^3] whose kept soil is ``kept`` (:func:`kept_volume` inverted, in closed form:
    ``u = v / (1 - (v / C_free)^p)^(1/p)``, ``v = kept - V_0``, ``R = u / r``); inf at or above the heaped
    capacity."""
    free = options.heap_factor * capacity - initial
    v = kept - initial
    if v <= 0.0:
        return 0.0
    if free <= 0.0 or v >= free:
        return math.inf
    p = options.sharpness
    return v / (1.0 - (v / free) ** p) ** (1.0 / p) / options.retention


def kept_fill(state: ContactState, capacity: float, options: PayloadOptions, initial: float = 0.0) -> float:
    """The kept fill [m^3] at the end of a path whose contact state carries its carving."""
    if state.carve is None:
        raise ParameterError("kept_fill needs a contact state computed by carving (fill='model')")
    return float(kept_volume(state.carve.removed_history[-1], capacity, options, initial))


def payload_contact_state(log: CycleLog, options: PayloadOptions,
                          slope_window: float = DEFAULT_SLOPE_WINDOW) -> ContactState:
    """The log's contact state under the ``"fee-payload"`` force model (:func:`with_payload`).

    The carving follows the log's pile and path (``fill='model'``): the surcharge sees the carved fill, the
    carried load the payload's kept soil. A logged load or fill is not used: this is what the model predicts
    for the path.
    """
    return with_payload(log.contact_state(slope_window=slope_window, fill="model"), log.bucket.capacity, options)


def with_payload(state: ContactState, capacity: float, options: PayloadOptions,
                 initial: float = 0.0) -> ContactState:
    """``state`` (computed by carving) with the payload's kept soil as its carried volume.

    The surcharge ``W_load N_q`` keeps the FEE's carved fill; the carried-load term
    (:attr:`~wheelloader.estimator.validity.ModelOptions.carried_in_soil` False) puts the kept soil's weight on
    the bucket as the tip leaves the soil. Measured on ``data/mpm`` (``docs/guide/force_models.md``): the kept
    soil as the surcharge's fill, or its weight added in soil, made unseen paths worse in soil.
    """
    if state.carve is None:
        raise ParameterError("the payload model needs the carved volume (a contact state computed by carving)")
    kept = kept_volume(state.carve.removed_history, capacity, options, initial)
    return replace(state, carried_volume=np.asarray(kept, dtype=float), measured_load=None)


def with_kept_fill(state: ContactState, capacity: float, options: PayloadOptions,
                   initial: float = 0.0) -> ContactState:
    """``state`` (computed by carving) with the payload's kept soil as its fill and no logged load."""
    if state.carve is None:
        raise ParameterError("the payload model needs the carved volume (a contact state computed by carving)")
    fill = kept_volume(state.carve.removed_history, capacity, options, initial)
    return replace(state, fill_volume=np.asarray(fill, dtype=float), measured_load=None)


#: The parameters :func:`fit_payload` may fit, in ``PayloadOptions`` order, with their bounds.
PAYLOAD_FIELDS: tuple[str, ...] = ("retention", "heap_factor", "sharpness")
_BOUNDS = {"retention": (1e-3, 1.0), "heap_factor": (1e-2, 10.0), "sharpness": (1.0, 50.0)}


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
                free: Sequence[str] = PAYLOAD_FIELDS, initial: PayloadOptions | None = None,
                density: float | None = None) -> PayloadOptions:
    """Calibrate the payload ``(r, h, p)`` to logs that carry the kept fill or the load.

    Least squares on the relative error of the kept fill along each path, every sample where the log's fill is
    above 2 % of the capacity weighted alike (so a cycle's end and its rise both count). A log's kept fill is
    its ``fill_volume`` (the plant's kept soil; the env's fill under ``"fee-payload"``), else its logged load
    over ``gamma g`` (:func:`logged_kept`); logs with neither are skipped.

    Parameters
    ----------
    logs : sequence of CycleLog
        The cycles.
    slope_window : float
        As :meth:`CycleLog.contact_state` (the carving of each path gives the removed volume).
    free : sequence of str
        The parameters fitted (names of :data:`PAYLOAD_FIELDS`); the others stay at ``initial``'s. A cycle
        that does not fill the bucket to its heap identifies the retention only: ``free=("retention",)``.
    initial : PayloadOptions, optional
        The start of the fit and the values of the held parameters (default ``(0.9, 0.7, 2.0)``).
    density : float, optional
        Soil density [kg/m^3] of logs that carry a load but no fill (default: each log's true soil).

    Raises
    ------
    CalibrationError
        If no log carries a fill or a load.
    """
    from scipy.optimize import least_squares

    unknown = sorted(set(free) - set(PAYLOAD_FIELDS))
    if unknown or not free:
        raise ParameterError(f"fit_payload: free must name some of {list(PAYLOAD_FIELDS)}, got {list(free)}")
    start = initial or PayloadOptions(0.9, 0.7, 2.0)
    removed, kept, caps = [], [], []
    for log in logs:
        logged = logged_kept(log, density)
        if logged is None:
            continue
        state = log.contact_state(slope_window=slope_window, fill="model")
        mask = logged > 0.02 * log.bucket.capacity
        removed.append(state.carve.removed_history[mask])
        kept.append(logged[mask])
        caps.append(np.full(int(mask.sum()), log.bucket.capacity))
    if not removed or sum(r.size for r in removed) == 0:
        raise CalibrationError("fit_payload needs logs with a logged fill_volume or load (the plant's kept soil)")
    r_all, k_all, c_all = (np.concatenate(v) for v in (removed, kept, caps))
    names = [name for name in PAYLOAD_FIELDS if name in free]

    def options(theta: np.ndarray) -> PayloadOptions:
        return replace(start, **{name: float(t) for name, t in zip(names, theta, strict=True)})

    def residual(theta: np.ndarray) -> np.ndarray:
        opts = options(theta)
        heaped = opts.heap_factor * c_all
        u = opts.retention * r_all
        model = u / (1.0 + (u / heaped) ** opts.sharpness) ** (1.0 / opts.sharpness)
        return (model - k_all) / k_all

    scale = {"retention": 0.1, "heap_factor": 0.1, "sharpness": 1.0}
    fit = least_squares(residual, x0=[getattr(start, n) for n in names],
                        bounds=([_BOUNDS[n][0] for n in names], [_BOUNDS[n][1] for n in names]),
                        x_scale=[scale[n] for n in names])
    return options(fit.x)
