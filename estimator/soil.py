"""Soil parameters of the modified Fundamental Earthmoving Equation.

The eight parameters of the paper's Table 1, their bounds (Section III-A) and
named presets. All values are SI: kg/m^3, Pa, rad, N/m^(n+1), N/m^(n+2).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from .checks import check_finite, check_range
from .errors import ParameterError

#: Names of the eight soil parameters in the paper's order (eq 18).
PARAMETER_NAMES: tuple[str, ...] = (
    "gamma",
    "cohesion",
    "adhesion",
    "phi",
    "delta",
    "k_c",
    "k_phi",
    "n",
)

#: Units of each parameter, for tables and docs.
PARAMETER_UNITS: dict[str, str] = {
    "gamma": "kg/m^3",
    "cohesion": "Pa",
    "adhesion": "Pa",
    "phi": "rad",
    "delta": "rad",
    "k_c": "N/m^(n+1)",
    "k_phi": "N/m^(n+2)",
    "n": "-",
}

#: Paper bounds (Section III-A): (lower, upper) per parameter, SI units.
#: gamma 1297-2345 kg/m^3; C and C_a 0-50 kPa; phi and delta 0-45 deg;
#: k_c 0-10 kN/m^(n+1); k_phi 0-5000 kN/m^(n+2); n 0.11-1.53.
PAPER_BOUNDS: dict[str, tuple[float, float]] = {
    "gamma": (1297.0, 2345.0),
    "cohesion": (0.0, 50_000.0),
    "adhesion": (0.0, 50_000.0),
    "phi": (0.0, math.radians(45.0)),
    "delta": (0.0, math.radians(45.0)),
    "k_c": (0.0, 10_000.0),
    "k_phi": (0.0, 5_000_000.0),
    "n": (0.11, 1.53),
}

#: Physical domain of each parameter, wider than the paper's calibration bounds: values outside are not
#: impossible for the model but are not soil (bulk densities of peat to dense rock fill; cohesion and adhesion
#: up to very stiff clay; friction angles up to the steepest granular soils; Bekker moduli and exponents over
#: the ranges of Wong's tables, paper Table A2, with a wide margin). :meth:`SoilParams.physical_warnings`.
PHYSICAL_RANGES: dict[str, tuple[float, float]] = {
    "gamma": (800.0, 3000.0),
    "cohesion": (0.0, 500_000.0),
    "adhesion": (0.0, 500_000.0),
    "phi": (0.0, math.radians(55.0)),
    "delta": (0.0, math.radians(55.0)),
    "k_c": (0.0, 1e6),
    "k_phi": (0.0, 1e8),
    "n": (0.05, 2.0),
}

# Relative slack when checking bounds, so values printed and read back with
# rounding (e.g. 45 deg written as 0.7854 rad) are still accepted.
_BOUND_SLACK = 1e-6


@dataclass(frozen=True)
class SoilParams:
    """The eight soil parameters of the modified FEE (paper Table 1, eq 18).

    Parameters
    ----------
    gamma : float
        Bulk density gamma [kg/m^3]. The paper writes gamma for density and
        multiplies by g in eq 1.
    cohesion : float
        Soil cohesion C [Pa].
    adhesion : float
        Soil-bucket adhesion C_a [Pa].
    phi : float
        Internal friction angle [rad].
    delta : float
        External (soil-steel) friction angle [rad].
    k_c : float
        Bekker cohesive modulus of deformation [N/m^(n+1)].
    k_phi : float
        Bekker frictional modulus of deformation [N/m^(n+2)].
    n : float
        Bekker exponent of deformation [-].

    Notes
    -----
    ``k_c`` and ``k_phi`` enter the forces only through the penetration
    pressure ``P = (k_c / b + k_phi) d^n`` (eq 15), i.e. through the single
    combination :meth:`sinkage_modulus` for a given cutting-edge thickness
    ``b``. Force data cannot separate them; the estimator reports this.

    Validation checks finiteness and the physical domain (non-negative
    moduli, angles in [0, pi/2), n > 0). Whether the values lie inside the
    paper's calibration bounds is a separate question: see
    :meth:`check_bounds`.
    """

    gamma: float
    cohesion: float
    adhesion: float
    phi: float
    delta: float
    k_c: float
    k_phi: float
    n: float

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_finite(f"SoilParams.{f.name}", getattr(self, f.name)))
        check_range("SoilParams.gamma", self.gamma, 0.0, None, low_open=True)  # kg/m^3
        for name in ("cohesion", "adhesion", "k_c", "k_phi"):
            check_range(f"SoilParams.{name}", getattr(self, name), 0.0, None)
        for name in ("phi", "delta"):
            value = getattr(self, name)
            if not 0.0 <= value < math.pi / 2:
                hint = " (it looks like degrees; angles are in radians)" if value >= math.pi / 2 else ""
                raise ParameterError(f"SoilParams.{name} must be in [0, pi/2) rad, got {value!r}{hint}")
        check_range("SoilParams.n", self.n, 0.0, None, low_open=True)

    # ------------------------------------------------------------------ views
    def sinkage_modulus(self, edge_thickness: float) -> float:
        """The identifiable Bekker combination ``k_c / b + k_phi`` [N/m^(n+2)] (eq 15)."""
        check_range("edge_thickness", edge_thickness, 0.0, None, low_open=True)  # m
        return self.k_c / edge_thickness + self.k_phi

    def to_array(self) -> np.ndarray:
        """Parameters as a float array in :data:`PARAMETER_NAMES` order."""
        return np.array([getattr(self, name) for name in PARAMETER_NAMES], dtype=float)

    @classmethod
    def from_array(cls, values: Any) -> SoilParams:
        """Build from an array-like in :data:`PARAMETER_NAMES` order."""
        arr = np.asarray(values, dtype=float).ravel()
        if arr.size != len(PARAMETER_NAMES):
            raise ParameterError(f"expected {len(PARAMETER_NAMES)} soil parameters, got {arr.size}")
        return cls(*(float(v) for v in arr))

    def to_dict(self) -> dict[str, float]:
        """Plain ``dict`` of SI values (JSON-serialisable)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> SoilParams:
        """Build from a mapping with exactly the eight parameter names."""
        if not isinstance(data, dict):
            raise ParameterError(f"soil parameters must be a mapping, got {type(data).__name__}")
        missing = [name for name in PARAMETER_NAMES if name not in data]
        unknown = [key for key in data if key not in PARAMETER_NAMES]
        if missing or unknown:
            raise ParameterError(
                f"soil parameter mapping: missing {missing or 'none'}, unknown {unknown or 'none'}; "
                f"expected keys {list(PARAMETER_NAMES)}"
            )
        return cls(**{name: data[name] for name in PARAMETER_NAMES})

    def replace(self, **changes: float) -> SoilParams:
        """Copy with some parameters changed (validated again)."""
        values = self.to_dict()
        for key in changes:
            if key not in values:
                raise ParameterError(f"unknown soil parameter {key!r}; expected one of {list(PARAMETER_NAMES)}")
        values.update(changes)
        return SoilParams(**values)

    def out_of_bounds(self, bounds: dict[str, tuple[float, float]] | None = None) -> list[str]:
        """Names of parameters outside ``bounds`` (default: the paper's)."""
        bounds = PAPER_BOUNDS if bounds is None else bounds
        bad = []
        for name, (lo, hi) in bounds.items():
            value = getattr(self, name)
            slack = _BOUND_SLACK * max(1.0, abs(lo), abs(hi))
            if value < lo - slack or value > hi + slack:
                bad.append(name)
        return bad

    def check_bounds(self, bounds: dict[str, tuple[float, float]] | None = None) -> SoilParams:
        """Raise :class:`ParameterError` if any parameter is outside ``bounds``; return self."""
        bounds = PAPER_BOUNDS if bounds is None else bounds
        bad = self.out_of_bounds(bounds)
        if bad:
            details = ", ".join(f"{name}={getattr(self, name):g} not in {bounds[name]}" for name in bad)
            raise ParameterError(f"soil parameters outside bounds: {details}")
        return self

    def physical_warnings(self) -> list[str]:
        """One message per parameter outside :data:`PHYSICAL_RANGES` (empty list: a plausible soil).

        The constructor only rejects what the model cannot evaluate (negative
        moduli, angles outside [0, pi/2), n <= 0); a density of 1e6 kg/m^3 or a
        cohesion of 1 GPa pass it but describe no soil. Callers decide whether
        a warning is an error (the CLI's ``--strict``).
        """
        out = []
        for name, (lo, hi) in PHYSICAL_RANGES.items():
            value = getattr(self, name)
            if not lo <= value <= hi:
                if name in ("phi", "delta"):
                    deg = math.degrees
                    shown = f"{deg(value):.4g} deg, physical range {deg(lo):g}-{deg(hi):g} deg"
                else:
                    unit = "" if PARAMETER_UNITS[name] == "-" else " " + PARAMETER_UNITS[name]
                    shown = f"{value:.4g}{unit}, physical range {lo:g}-{hi:g}{unit}"
                out.append(f"{name} = {shown}")
        return out

    def describe(self) -> str:
        """Human-readable one-parameter-per-line summary (angles in degrees)."""
        lines = []
        for name in PARAMETER_NAMES:
            value = getattr(self, name)
            if name in ("phi", "delta"):
                lines.append(f"{name:>9} = {value:.4f} rad ({math.degrees(value):.2f} deg)")
            else:
                lines.append(f"{name:>9} = {format_value(value)} {PARAMETER_UNITS[name]}")
        return "\n".join(lines)


#: Magnitudes below this print as 0 (a bounded solver's 1e-18 Pa cohesion is its lower bound, zero).
PRINT_ZERO_BELOW = 1e-9


def format_value(value: float, digits: int = 6) -> str:
    """``value`` for people: ``digits`` significant digits, and ``0`` for magnitudes below
    :data:`PRINT_ZERO_BELOW` (numerical dust from the solvers, e.g. ``3.7e-18 Pa``)."""
    if math.isfinite(value) and abs(value) < PRINT_ZERO_BELOW:
        return "0"
    return f"{value:.{digits}g}"


def validate_bounds(bounds: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    """Check a bounds mapping (known names, finite, lower <= upper) and fill in paper defaults."""
    if not isinstance(bounds, dict):
        raise ParameterError(f"bounds must be a dict name -> (lower, upper), got {type(bounds).__name__}")
    out = dict(PAPER_BOUNDS)
    for name, pair in bounds.items():
        if name not in PAPER_BOUNDS:
            raise ParameterError(f"bounds: unknown parameter {name!r}; expected one of {list(PARAMETER_NAMES)}")
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ParameterError(f"bounds[{name!r}] must be a pair (lower, upper), got {pair!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise ParameterError(f"bounds[{name!r}] must be finite, got {(lo, hi)!r}")
        if lo > hi:
            raise ParameterError(f"bounds[{name!r}] are inverted: lower {lo!r} > upper {hi!r}")
        _check_physical_bounds(name, lo, hi)
        out[name] = (lo, hi)
    return out


def _check_physical_bounds(name: str, lo: float, hi: float) -> None:
    """Bounds must lie in the domain :class:`SoilParams` accepts (else the fit would leave it)."""
    if name in ("phi", "delta"):
        if lo < 0.0 or hi >= math.pi / 2:
            hint = " (they look like degrees; angles are in radians)" if hi >= math.pi / 2 else ""
            raise ParameterError(f"bounds[{name!r}] must lie in [0, pi/2) rad, got {(lo, hi)!r}{hint}")
    elif name in ("gamma", "n"):
        if lo <= 0.0:
            raise ParameterError(f"bounds[{name!r}] must be > 0, got {(lo, hi)!r}")
    elif lo < 0.0:
        raise ParameterError(f"bounds[{name!r}] must be >= 0, got {(lo, hi)!r}")


def _deg(value: float) -> float:
    return math.radians(value)


# --------------------------------------------------------------------- presets
# The four Algoryx soils of the paper (Table 2), as FEE parameters. Table 2 /
# Table 4 (AGX column) give density, cohesion, adhesion (particle-terrain
# cohesion) and internal friction; the remaining parameters (delta, k_c,
# k_phi, n) have no Algoryx counterpart and are the paper's multi-stage
# estimates from Table 4 (PE column). "sand" has no Table 4 column; it
# takes the estimates of "modified sand", whose particle properties it shares.
_PRESETS: dict[str, SoilParams] = {
    "gravel": SoilParams(
        gamma=1474.0, cohesion=0.0, adhesion=0.0, phi=0.7679, delta=0.63, k_c=1274.0, k_phi=177.4, n=1.21
    ),
    "sand": SoilParams(
        gamma=1474.0, cohesion=0.0, adhesion=0.0, phi=0.6807, delta=0.66, k_c=1807.6, k_phi=188.0, n=1.50
    ),
    "dirt": SoilParams(
        gamma=1474.0, cohesion=2100.0, adhesion=2500.0, phi=0.6978, delta=0.39, k_c=5486.1, k_phi=261.3, n=1.44
    ),
    "modified_sand": SoilParams(
        gamma=1874.5, cohesion=0.0, adhesion=0.0, phi=0.5934, delta=0.66, k_c=1807.6, k_phi=188.0, n=1.50
    ),
    # Literature soils: Table A1 (USCS class: density range mid-point,
    # cohesion, friction angle; delta = 2/3 phi after Lindeburg/Broms, steel
    # bucket) combined with the Table A2 Bekker row of the same soil family.
    # Adhesion: 0 for cohesionless soils, half the cohesion for clays (inside
    # Table A1's "soil state" adhesion ranges). Only rows whose k_c lies in
    # the paper's bounds are used.
    "dry_sand": SoilParams(  # SP poorly graded sand + Dry Sand (LLL)
        gamma=1844.5, cohesion=0.0, adhesion=0.0, phi=_deg(36.0), delta=_deg(24.0), k_c=990.0, k_phi=1.52e6, n=1.10
    ),
    "lean_clay": SoilParams(  # CL lean clay + Lean Clay WES 32
        gamma=1360.0, cohesion=20_000.0, adhesion=10_000.0, phi=_deg(27.0), delta=_deg(18.0),
        k_c=1520.0, k_phi=1.19e5, n=0.15,
    ),
    "fat_clay": SoilParams(  # CH fat clay + Heavy Clay WES 40
        gamma=1400.0, cohesion=25_000.0, adhesion=12_500.0, phi=_deg(22.0), delta=_deg(14.67),
        k_c=1840.0, k_phi=1.03e5, n=0.11,
    ),
}

#: Names of the built-in presets.
PRESET_NAMES: tuple[str, ...] = tuple(_PRESETS)


def preset(name: str) -> SoilParams:
    """Return a named soil preset.

    Parameters
    ----------
    name : str
        One of :data:`PRESET_NAMES`: the paper's four Algoryx soils
        ``"gravel"``, ``"sand"``, ``"dirt"``, ``"modified_sand"`` (Table 2
        with Table 4 estimates for parameters Algoryx does not have), and
        literature soils ``"dry_sand"``, ``"lean_clay"``, ``"fat_clay"``
        (Tables A1 + A2). Hyphens and spaces are accepted for underscores.
    """
    if not isinstance(name, str):
        raise ParameterError(f"soil preset name must be a string, got {type(name).__name__}")
    key = name.strip().lower().replace("-", "_").replace(" ", "_")
    if key not in _PRESETS:
        raise ParameterError(f"unknown soil preset {name!r}; choose one of {list(PRESET_NAMES)}")
    return _PRESETS[key]


def as_soil(soil: SoilParams | str | dict[str, Any]) -> SoilParams:
    """Coerce a preset name, a mapping or a :class:`SoilParams` to :class:`SoilParams`."""
    if isinstance(soil, SoilParams):
        return soil
    if isinstance(soil, str):
        return preset(soil)
    if isinstance(soil, dict):
        return SoilParams.from_dict(soil)
    raise ParameterError(f"soil must be a SoilParams, a preset name or a dict, got {type(soil).__name__}")
