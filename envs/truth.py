"""Truth beyond the force model: effects the FEE model cannot represent.

When the env plays the plant (the "true" soil the estimator must discover),
these options make its forces differ from anything the calibrated model can
produce, so adaptation benchmarks are not circular. All are off by default.

Effects, applied in this order to the model forces ``F_T, F_N`` of a step
with the tip in soil (depth ``d`` > 0):

1. compaction: both forces are multiplied by ``1 + compaction * d``
   (density and strength that grow with depth below the start surface);
2. rate-dependent resistance: ``F_T += rate_resistance * w * d * |v|`` with
   bucket width ``w`` and tip speed ``|v|`` (a viscous term the quasi-static
   FEE lacks);
3. stones: per metre travelled in soil a stone is hit with probability
   ``stone_rate``; it adds a spike of exponentially distributed size (mean
   ``stone_force``) to ``F_T`` and half of it to ``F_N``, decaying with time
   constant ``stone_duration`` (also out of soil);
4. drift (between cycles): each soil parameter is multiplied by
   ``exp(drift * N(0, 1))`` at every new cycle when the soil is kept
   (clipped to the paper's bounds).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from wheelloader.estimator import ParameterError
from wheelloader.estimator.checks import check_range


@dataclass(frozen=True)
class TruthOptions:
    """Beyond-model effects of the simulated plant (all off by default).

    Parameters
    ----------
    compaction : float
        Relative force increase per metre of depth [1/m]. Default 0.
    rate_resistance : float
        Viscous resistance coefficient [N s/m^3]: ``dF_T = c w d |v|``. Default 0.
        About 2e4 gives a few kN at 0.5 m/s and 0.3 m depth.
    stone_rate : float
        Stones per metre of tip travel in soil [1/m]. Default 0.
    stone_force : float
        Mean stone force spike [N]. Default 5000.
    stone_duration : float
        Decay time constant of a spike [s]. Default 0.05.
    drift : float
        Log-normal drift scale of every soil parameter between cycles [-]. Default 0.
    """

    compaction: float = 0.0
    rate_resistance: float = 0.0
    stone_rate: float = 0.0
    stone_force: float = 5000.0
    stone_duration: float = 0.05
    drift: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = check_range(f"TruthOptions.{f.name}", getattr(self, f.name), 0.0,
                                low_open=f.name == "stone_duration")
            object.__setattr__(self, f.name, value)

    @property
    def active(self) -> bool:
        """True when any in-cycle effect (compaction, rate, stones) is on."""
        return self.compaction > 0.0 or self.rate_resistance > 0.0 or self.stone_rate > 0.0

    def to_dict(self) -> dict[str, float]:
        """JSON-able mapping."""
        return asdict(self)


def as_truth(value: TruthOptions | Mapping[str, float] | None) -> TruthOptions:
    """Coerce ``None`` (all off), a mapping or :class:`TruthOptions`."""
    if value is None:
        return TruthOptions()
    if isinstance(value, TruthOptions):
        return value
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {f.name for f in fields(TruthOptions)})
        if unknown:
            raise ParameterError(f"truth: unknown option(s) {unknown}; expected some of "
                                 f"{[f.name for f in fields(TruthOptions)]}")
        return TruthOptions(**value)
    raise ParameterError(f"truth must be a TruthOptions, a dict or None, got {type(value).__name__}")


def stone_decay(options: TruthOptions, dt: float) -> float:
    """Per-step decay factor of a stone spike."""
    return math.exp(-dt / options.stone_duration)


def model_excess(options: TruthOptions, f_t: Any, f_n: Any, depth: Any, speed: Any, width: float, *,
                 where: Callable[[Any, Any, Any], Any] = np.where) -> tuple[Any, Any]:
    """Effects 1 and 2 on the model forces ``F_T, F_N`` [N] where the tip is in soil (``depth > 0`` [m]):
    compaction and rate-dependent resistance at tip ``speed`` [m/s] with bucket ``width`` [m].

    ``where(condition, a, b)`` is the backend's select (``numpy.where``, or a conditional for floats).
    """
    ins = depth > 0.0
    factor = 1.0 + options.compaction * depth
    return (where(ins, f_t * factor + options.rate_resistance * width * depth * speed, f_t),
            where(ins, f_n * factor, f_n))


def stone_step(options: TruthOptions, stone: Any, depth: Any, dist: Any, u_hit: Any, u_size: Any, decay: float, *,
               where: Callable[[Any, Any, Any], Any] = np.where,
               log1p: Callable[[Any], Any] = np.log1p) -> Any:
    """Effect 3 over one step: the stone spike [N] decays by ``decay`` (:func:`stone_decay`), and with the
    tip in soil a new stone is hit when ``u_hit < stone_rate * dist`` (``dist``: tip travel of the step [m];
    ``u_hit``, ``u_size``: uniforms in [0, 1)). The spike adds to ``F_T`` and half of it to ``F_N``."""
    stone = stone * decay
    if options.stone_rate > 0.0:
        hit = (depth > 0.0) & (u_hit < options.stone_rate * dist)
        stone = where(hit, stone + stone_size(options, u_size, log1p=log1p), stone)
    return stone


def stone_size(options: TruthOptions, u: Any, *, log1p: Callable[[Any], Any] = math.log1p) -> Any:
    """Exponentially distributed spike size [N] from a uniform ``u`` in [0, 1) (``log1p``: the backend's,
    ``math.log1p`` for a float, ``numpy.log1p`` for an array)."""
    return -options.stone_force * log1p(-u)
