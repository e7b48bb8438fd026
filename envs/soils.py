"""The hidden soil of the envs: fixed, or a distribution for domain randomisation, and its drift."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wheelloader.estimator import (
    PAPER_BOUNDS,
    PARAMETER_NAMES,
    PRESET_NAMES,
    ParameterError,
    SoilParams,
    as_soil,
)

__all__ = ["SoilRandomization", "SoilSpec", "drift_soil", "parse_soil"]


@dataclass(frozen=True)
class SoilRandomization:
    """A distribution of hidden soils for domain randomisation.

    Parameters
    ----------
    base : SoilParams or str
        Soil whose parameters are used where ``ranges`` says nothing.
    ranges : dict
        ``name -> (low, high)`` in SI units: the parameter is drawn uniformly.
    choices : tuple of str or SoilParams
        If given, each reset first picks one of these soils uniformly as the
        base (then ``ranges`` apply).
    """

    base: SoilParams | str = "gravel"
    ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    choices: tuple[SoilParams | str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "base", as_soil(self.base))
        object.__setattr__(self, "choices", tuple(as_soil(c) for c in self.choices))
        clean: dict[str, tuple[float, float]] = {}
        for name, pair in dict(self.ranges).items():
            if name not in PARAMETER_NAMES:
                raise ParameterError(f"soil range: unknown parameter {name!r}; expected one of {list(PARAMETER_NAMES)}")
            try:
                lo, hi = (float(v) for v in pair)
            except (TypeError, ValueError):
                raise ParameterError(f"soil range {name!r} must be a pair (low, high), got {pair!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ParameterError(f"soil range {name!r} must be finite with low <= high, got {(lo, hi)!r}")
            clean[name] = (lo, hi)
        object.__setattr__(self, "ranges", clean)
        # Validate the corners now rather than at the first reset.
        self.base.replace(**{k: v[0] for k, v in clean.items()})
        self.base.replace(**{k: v[1] for k, v in clean.items()})

    def sample(self, rng: np.random.Generator) -> SoilParams:
        """Draw one soil (uses ``rng`` in a fixed order: choice, then ranges in parameter order)."""
        base = self.base
        if self.choices:
            base = self.choices[int(rng.integers(len(self.choices)))]
        if not self.ranges:
            return base
        names = [n for n in PARAMETER_NAMES if n in self.ranges]
        u = rng.random(len(names))
        values = {}
        for n, ui in zip(names, u, strict=True):
            lo, hi = self.ranges[n]
            values[n] = lo + float(ui) * (hi - lo)
        return base.replace(**values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able description."""
        return {"base": self.base.to_dict(), "ranges": {k: list(v) for k, v in self.ranges.items()},
                "choices": [c.to_dict() for c in self.choices]}


SoilSpec = SoilParams | SoilRandomization


def parse_soil(soil: Any) -> SoilSpec:
    """Parse the ``soil`` argument of the envs.

    Accepted: a preset name; ``"random"`` (uniform over the presets); a
    :class:`SoilParams`; a dict of the eight parameters; a dict
    ``{name: (low, high), ...}`` of ranges (optionally with a ``"base"`` key);
    a list of presets / soils (uniform choice); a :class:`SoilRandomization`.
    """
    if isinstance(soil, (SoilParams, SoilRandomization)):
        return soil
    if isinstance(soil, str):
        if soil.strip().lower() == "random":
            return SoilRandomization(base=PRESET_NAMES[0], choices=PRESET_NAMES)
        return as_soil(soil)
    if isinstance(soil, Mapping):
        data = dict(soil)
        if any(isinstance(v, (tuple, list)) for v in data.values()):
            base = data.pop("base", "gravel")
            choices = data.pop("choices", ())
            return SoilRandomization(base=base, ranges=data, choices=tuple(choices))
        return as_soil(data)
    if isinstance(soil, Sequence) and soil and all(isinstance(s, (str, SoilParams)) for s in soil):
        return SoilRandomization(base=as_soil(soil[0]), choices=tuple(soil))
    raise ParameterError(
        f"soil must be a preset name, 'random', SoilParams, a parameter dict, a range dict or a list of soils; "
        f"got {soil!r}"
    )


def drift_soil(soil: SoilParams, drift: float, rng: np.random.Generator) -> SoilParams:
    """Random-walk drift of every parameter by a factor ``exp(drift * N(0, 1))``, clipped to the paper bounds."""
    z = rng.standard_normal(len(PARAMETER_NAMES))
    values = {}
    for name, zi in zip(PARAMETER_NAMES, z, strict=True):
        lo, hi = PAPER_BOUNDS[name]
        values[name] = min(max(getattr(soil, name) * math.exp(drift * float(zi)), lo), hi)
    return SoilParams(**values)
