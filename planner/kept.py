"""The kept-payload objective (opt-in, ``PlannerOptions(objective="kept_per_energy")``): energy per m^3 of kept soil.

A user pays per tonne moved, not per m^3 carved. The plant keeps only part of what a path removes
(:mod:`wheelloader.estimator.payload`), and a path that ends low leaves the lift of its load to the dump for
later. This objective counts both:

    V_kept = kept_volume(V_carved)                                   (payload state, estimator/payload.py)
    E_lift = gamma g V_kept max(z_dump - z_end, 0)                   (the load lifted on to a common height)
    J      = (E_dig + E_lift) / V_kept                               [J/m^3]

``E_dig`` is the env's energy bookkeeping along the path (work on the soil plus the lift of the carried load,
:func:`~wheelloader.envs.bookkeeping.step_work`); ``z_dump`` the dump height (default: the end height of the
fixed Bezier path, :func:`dump_height`, the same on every pile since that path is only slid along x). The
planner constrains ``V_kept >= target`` (default: the fixed path's kept fill on the same pile,
:func:`fixed_kept_fill`).

:func:`kept_terms` is written once for NumPy and CasADi (``pos`` is the positive part: the NLP passes a smooth
one), so the NLP and the NumPy check evaluate the same formula.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wheelloader.estimator import GRAVITY, Bucket, Pile, default_path
from wheelloader.estimator.payload import PayloadOptions, exit_angle_profile, kept_volume

from .fallback import LOOP_EXIT_MIN_FILL, _kept, bezier_on_face

__all__ = ["KEPT_OBJECTIVE_SCALE", "KeptTerms", "dump_height", "evaluate", "fixed_kept_fill", "kept_terms",
           "smooth_lift"]

#: Scale of the NLP's objective [J per bucket]: J / scale * capacity is O(1) (10 kJ per bucket).
KEPT_OBJECTIVE_SCALE = 1.0e4
#: Width of the smooth positive part of the lift height in the NLP [m].
LIFT_SMOOTHING = 1e-3


@dataclass(frozen=True)
class KeptTerms:
    """The kept-payload objective's terms (SI units).

    Attributes
    ----------
    kept : float
        Kept soil V_kept [m^3].
    lift_energy : float
        Energy to lift it on to the dump height [J].
    energy : float
        Digging energy plus ``lift_energy`` [J].
    per_kept : float
        ``energy / kept`` [J/m^3] (inf when nothing is kept).
    """

    kept: float
    lift_energy: float
    energy: float
    per_kept: float

    def to_dict(self) -> dict[str, float]:
        """Plain-JSON form."""
        return {"kept": self.kept, "lift_energy": self.lift_energy, "energy": self.energy,
                "per_kept": self.per_kept}


def smooth_lift(v, eps: float = LIFT_SMOOTHING, sqrt: Callable = np.sqrt):
    """Smooth ``max(v, 0)`` (``(v + sqrt(v^2 + eps^2)) / 2``), the NLP's positive part of the lift height."""
    return 0.5 * (v + sqrt(v * v + eps * eps))


def kept_terms(carved, dig_energy, z_end, gamma: float, capacity: float, payload: PayloadOptions,
               z_dump: float, pos: Callable = lambda v: np.maximum(v, 0.0), exit_angle=0.0):
    """``(kept, lift_energy, energy, energy / kept)`` of a path, on NumPy values or CasADi expressions.

    Parameters
    ----------
    carved : float or casadi expression
        Volume the path removes from the pile [m^3] (the FEE's fill).
    dig_energy : float or casadi expression
        The env's energy of the path [J].
    z_end : float or casadi expression
        Tip height at the path's end [m].
    gamma : float or casadi expression
        Soil density [kg/m^3].
    capacity : float
        The bucket's nominal capacity [m^3].
    payload : PayloadOptions
        The payload state's parameters.
    z_dump : float
        The dump height [m].
    pos : callable
        Positive part of the lift height (default the exact one; the NLP passes :func:`smooth_lift`).
    exit_angle : float or casadi expression
        Blade angle as the tip leaves the soil [rad]: the heaped capacity's, where ``payload`` has a ``curl_gain``.
    """
    kept = kept_volume(carved, capacity, payload, 0.0, exit_angle)
    lift = gamma * GRAVITY * kept * pos(z_dump - z_end)
    energy = dig_energy + lift
    return kept, lift, energy, energy / kept


def evaluate(carved: float, dig_energy: float, z_end: float, gamma: float, capacity: float,
             payload: PayloadOptions, z_dump: float, exit_angle: float = 0.0) -> KeptTerms:
    """:func:`kept_terms` on plain numbers (exact positive part) as :class:`KeptTerms`."""
    kept, lift, energy, _ = kept_terms(float(carved), float(dig_energy), float(z_end), gamma, capacity, payload,
                                       z_dump, exit_angle=float(exit_angle))
    kept, lift, energy = float(kept), float(lift), float(energy)
    return KeptTerms(kept, lift, energy, energy / kept if kept > 0.0 else float("inf"))


def dump_height(rate: float = 60.0) -> float:
    """The default dump height: the end height of the fixed Bezier path [m] (the same on every pile)."""
    return float(default_path(rate=rate).z[-1])


def fixed_kept_fill(pile: Pile, bucket: Bucket, payload: PayloadOptions, rate: float = 60.0,
                    exit_min_fill: float | None = None) -> float:
    """The payload model's kept fill [m^3] of the fixed Bezier path on ``pile`` (as the loop places it,
    :func:`~wheelloader.planner.bezier_on_face`, up to where the env would end its cycle)."""
    exit_min_fill = LOOP_EXIT_MIN_FILL if exit_min_fill is None else exit_min_fill
    path = bezier_on_face(pile, rate, bucket, exit_min_fill=exit_min_fill)
    _, end = _kept(pile, path.x, path.z, bucket, exit_min_fill)
    removed = pile.carve(path.x[:end + 1], path.z[:end + 1], bucket.width, bucket.capacity).removed
    x, z = path.x[:end + 1], path.z[:end + 1]
    exit_angle = exit_angle_profile(path.blade_angle[:end + 1], pile.surface_height(x) - z)[-1]
    return float(kept_volume(removed, bucket.capacity, payload, 0.0, exit_angle))
