"""Bucket and loader geometry and limits.

Defaults describe a compact wheel loader of the class of the paper's EVERUN
ER12 (operating mass about 1.2 t). The paper does not list the machine's
numbers; the defaults below are chosen, not measured, and each says how.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

from .checks import check_range
from .errors import ParameterError


def _check_positive(owner: object, *names: str) -> None:
    for name in names:
        value = check_range(f"{type(owner).__name__}.{name}", getattr(owner, name), 0.0, None, low_open=True)
        object.__setattr__(owner, name, value)


@dataclass(frozen=True)
class Bucket:
    """Rigid bucket of the loader.

    Parameters
    ----------
    width : float
        Bucket width w [m] (eqs 1, 16). Default 1.0 m: the width class of
        ER12-type compact loaders' standard buckets (about 1.0-1.2 m).
    edge_thickness : float
        Cutting-edge thickness b [m] (eqs 15-16). Default 0.02 m, a typical
        bolt-on cutting edge of a compact bucket.
    floor_length : float
        Length of the bucket floor from the cutting edge to the back [m];
        the longest blade length in soil L_t. Default 0.45 m, chosen so that
        floor length x width x a ~0.45 m high back gives the capacity below
        with a heaped profile.
    capacity : float
        Heaped bucket capacity [m^3]. Default 0.2 m^3, the usual size for the
        ER12 class.
    mass : float
        Empty bucket mass W_b [kg]. Default 90 kg.
    """

    width: float = 1.0
    edge_thickness: float = 0.02
    floor_length: float = 0.45
    capacity: float = 0.2
    mass: float = 90.0

    def __post_init__(self) -> None:
        _check_positive(self, *(f.name for f in fields(self)))

    @property
    def capacity_per_width(self) -> float:
        """Capacity per metre of width [m^2]: the quasi-2D cross-section it can hold."""
        return self.capacity / self.width

    def to_dict(self) -> dict[str, float]:
        """JSON-serialisable mapping."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Bucket:
        """Build from a mapping; unknown keys are an error."""
        return _from_dict(cls, data)


@dataclass(frozen=True)
class Loader:
    """Force and motion limits of the loader at the bucket.

    How the force limits were chosen: the FEE forces of the default path on
    the default pile with a full bucket reach F_T = 11.5 kN and F_N = 15.6 kN
    for the "gravel" preset (the largest of all presets; measured with
    ``soil_forces``), and the deepest Fig. 8-style path reaches 22 kN in
    clay. The defaults sit above the former and near the latter, so the
    default path never stalls while aggressive paths can. An ER12-class
    machine (1.2 t) has less tractive effort than 20 kN; set the limits of
    your own machine explicitly.

    Parameters
    ----------
    max_push_force : float
        Largest tangential (along-blade) soil force F_T the machine can
        overcome [N]. Default 20 kN.
    max_lift_force : float
        Largest normal (across-blade) soil force F_N the lift/tilt hydraulics
        can hold [N]. Default 25 kN.
    max_speed : float
        Largest bucket-tip speed along x and along z [m/s]. Default 1.0 m/s.
    max_tilt_rate : float
        Largest bucket tilt (curl) rate [rad/s]. Default 1.0 rad/s.
    max_acceleration : float
        Largest tip acceleration per axis [m/s^2]. Default 2.0 m/s^2.
    """

    max_push_force: float = 20_000.0
    max_lift_force: float = 25_000.0
    max_speed: float = 1.0
    max_tilt_rate: float = 1.0
    max_acceleration: float = 2.0

    def __post_init__(self) -> None:
        _check_positive(self, *(f.name for f in fields(self)))

    def to_dict(self) -> dict[str, float]:
        """JSON-serialisable mapping."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Loader:
        """Build from a mapping; unknown keys are an error."""
        return _from_dict(cls, data)


def _from_dict(cls: type, data: dict[str, Any]):
    if not isinstance(data, dict):
        raise ParameterError(f"{cls.__name__} must be given as a mapping, got {type(data).__name__}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ParameterError(f"{cls.__name__}: unknown field(s) {unknown}; expected some of {sorted(names)}")
    return cls(**data)
