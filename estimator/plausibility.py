"""Is a cycle log on a wheel loader's scale? One table of limits for the units a log can get wrong.

A log whose numbers are right but whose units are not (a pile in millimetres, time in milliseconds, a
tip in another height datum) still fits: the force model bends its soil parameters to match, and the fit
would be called trustworthy. Each quantity below has two bands. Outside the outer one the log is refused
(:class:`~wheelloader.estimator.errors.CycleLogError`, or :class:`ParameterError` for a pile on its own)
with the likely cause; outside the inner one it is accepted with a warning, and a calibration on it is
not trustworthy (:func:`plausibility_warnings`, fit-warning code ``implausible_log``).

=============================  ======  ==========  ==========  ==========  ==========  =========================
quantity                        unit   refuse <    warn <      warn >      refuse >    likely cause when refused
=============================  ======  ==========  ==========  ==========  ==========  =========================
pile height (max - min z)       m      --          --          10          50          pile z in mm or cm
pile length (max - min x)       m      --          --          100         500         pile x in mm or cm
cycle duration                  s      --          0.5         60          600         t in ms
sample rate (1 / median dt)     Hz     1           5           10 000      1e6         t in ms (or in us)
median tip depth in soil        m      --          --          1.5         2.5         z and pile in other frames
share of samples in soil        --     --          --          0.98        --          (warning only)
peak measured |F_R|             N      --          10          2e6         1e8         forces in kN / in mN
=============================  ======  ==========  ==========  ==========  ==========  =========================

The repository's 341 logs (``data/``, ``data/results/**/cycles``) lie inside every inner band: pile
heights 0.8-1.3 m, lengths 2.0-6.8 m, durations 4.7-6.5 s at 60 Hz, median depths in soil 0.05-0.31 m,
34-91 % of samples in soil, peak |F_R| 1.6-133 kN (``tests/test_plausibility.py`` checks them all).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import CycleLogError, ParameterError


@dataclass(frozen=True)
class Limit:
    """The bands of one quantity (``None``: no limit on that side); causes name the likely unit mix-up."""

    name: str
    unit: str
    refuse_below: float | None
    warn_below: float | None
    warn_above: float | None
    refuse_above: float | None
    cause_low: str = ""
    cause_high: str = ""


#: The table of the module docstring, by key.
LIMITS: dict[str, Limit] = {
    "pile_height": Limit("pile height", "m", None, None, 10.0, 50.0, cause_high="pile z looks like mm or cm"),
    "pile_length": Limit("pile length", "m", None, None, 100.0, 500.0, cause_high="pile x looks like mm or cm"),
    "duration": Limit("cycle duration", "s", None, 0.5, 60.0, 600.0, cause_high="t looks like ms"),
    "rate": Limit("sample rate", "Hz", 1.0, 5.0, 1e4, 1e6, cause_low="t looks like ms",
                  cause_high="t looks like us, not s"),
    "depth": Limit("median tip depth in soil", "m", None, None, 1.5, 2.5,
                   cause_high="the tip z and the pile surface look like different height datums (or units)"),
    "in_soil": Limit("share of samples in soil", "", None, None, 0.98, None),
    "peak_force": Limit("peak measured |F_R|", "N", None, 10.0, 2e6, 1e8, cause_low="forces look like kN",
                        cause_high="forces look like mN"),
}


def _judge(key: str, value: float, refused: list[str], warned: list[str]) -> None:
    lim = LIMITS[key]
    shown = f"{lim.name} {value:.3g}{(' ' + lim.unit) if lim.unit else ''}"
    if lim.refuse_below is not None and value < lim.refuse_below:
        refused.append(f"{shown} is below {lim.refuse_below:g}: {lim.cause_low}")
    elif lim.refuse_above is not None and value > lim.refuse_above:
        refused.append(f"{shown} is above {lim.refuse_above:g}: {lim.cause_high}")
    elif lim.warn_below is not None and value < lim.warn_below:
        warned.append(f"{shown} is below {lim.warn_below:g}, unusual for a wheel loader")
    elif lim.warn_above is not None and value > lim.warn_above:
        warned.append(f"{shown} is above {lim.warn_above:g}, unusual for a wheel loader")


def _pile(x: np.ndarray, z: np.ndarray, refused: list[str], warned: list[str]) -> None:
    _judge("pile_height", float(np.max(z) - np.min(z)), refused, warned)
    _judge("pile_length", float(np.max(x) - np.min(x)), refused, warned)


def check_pile(pile, source: str = "pile") -> list[str]:
    """Warnings for a pile's scale; :class:`ParameterError` naming the likely cause when implausible."""
    refused: list[str] = []
    warned: list[str] = []
    _pile(pile.x, pile.heights, refused, warned)
    if refused:
        raise ParameterError(f"{source}: implausible for a wheel loader: " + "; ".join(refused))
    return warned


def check_path(path, source: str = "path") -> list[str]:
    """Warnings for a bucket path's time scale (duration, sample rate); :class:`ParameterError` naming the
    likely cause when implausible."""
    refused: list[str] = []
    warned: list[str] = []
    _time(path.t, refused, warned)
    if refused:
        raise ParameterError(f"{source}: implausible for a wheel loader: " + "; ".join(refused))
    return warned


def _time(t: np.ndarray, refused: list[str], warned: list[str]) -> None:
    _judge("duration", float(t[-1] - t[0]), refused, warned)
    _judge("rate", float(1.0 / np.median(np.diff(t))), refused, warned)


def _log(log) -> tuple[list[str], list[str]]:
    refused: list[str] = []
    warned: list[str] = []
    _pile(log.pile.x, log.pile.heights, refused, warned)
    _time(log.path.t, refused, warned)
    depth = log.pile.surface_height(log.path.x) - log.path.z
    soil = depth > 0.0
    if np.any(soil):
        _judge("depth", float(np.median(depth[soil])), refused, warned)
    _judge("in_soil", float(np.mean(soil)), refused, warned)
    _judge("peak_force", float(np.max(log.resultant)), refused, warned)
    return refused, warned


def check_log(log, source: str = "log") -> None:
    """:class:`CycleLogError` naming the likely cause when ``log`` is outside a refusal band."""
    refused, _ = _log(log)
    if refused:
        raise CycleLogError(f"{source}: implausible for a wheel loader: " + "; ".join(refused))


def plausibility_warnings(log) -> list[str]:
    """The inner-band warnings of a cycle log (empty: on a loader's scale everywhere)."""
    return _log(log)[1]
