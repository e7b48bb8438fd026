"""Argument checks shared by every layer.

One place for the validations that used to be written out by hand at each call site ("must be an int >= 1",
"must be finite", "must be one of ..."). Each check returns the value it accepted (converted where the check
says so) and raises the error class the caller names, so a planner option still raises
:class:`~wheelloader.estimator.errors.PlanningError` and an env setting
:class:`~wheelloader.estimator.errors.ParameterError`, with one wording everywhere.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from numbers import Integral, Real

from .errors import ParameterError

__all__ = ["check_choice", "check_finite", "check_int", "check_optional_int", "check_range"]


def check_int(name: str, value: object, *, minimum: int = 1, maximum: int | None = None,
              error: type[Exception] = ParameterError) -> int:
    """Return ``value`` as ``int`` if it is an integer (not a bool) in ``[minimum, maximum]``.

    Parameters
    ----------
    name : str
        The argument's name, as the message should show it.
    value : object
        What the caller passed.
    minimum, maximum : int, optional
        Inclusive bounds; ``maximum=None`` means unbounded above.
    error : type of Exception
        The class raised on a bad value.

    Raises
    ------
    error
        One line: ``"<name> must be an int >= <minimum>, got <value!r>"`` (or ``in [minimum, maximum]``).
    """
    ok = isinstance(value, Integral) and not isinstance(value, bool)
    if ok:
        ok = value >= minimum and (maximum is None or value <= maximum)
    if not ok:
        domain = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"
        raise error(f"{name} must be an int {domain}, got {value!r}")
    return int(value)


def check_optional_int(name: str, value: object, *, minimum: int = 1, maximum: int | None = None,
                       error: type[Exception] = ParameterError) -> int | None:
    """:func:`check_int` that also accepts ``None`` (returned as is)."""
    return None if value is None else check_int(name, value, minimum=minimum, maximum=maximum, error=error)


def check_finite(name: str, value: object, *, error: type[Exception] = ParameterError) -> float:
    """Return ``value`` as ``float`` if it is a finite real number (not a bool)."""
    if not (isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(float(value))):
        raise error(f"{name} must be a finite number, got {value!r}")
    return float(value)


def check_range(name: str, value: object, low: float | None = None, high: float | None = None, *,
                low_open: bool = False, high_open: bool = False,
                error: type[Exception] = ParameterError) -> float:
    """Return ``value`` as ``float`` if it is finite and inside the interval given.

    ``low``/``high`` of ``None`` leave that side unbounded; ``low_open``/``high_open`` exclude the end point.
    The message names the interval, e.g. ``"dt must be in (0, 1], got 0"``.
    """
    x = check_finite(name, value, error=error)
    bad = (low is not None and (x <= low if low_open else x < low)) or \
          (high is not None and (x >= high if high_open else x > high))
    if bad:
        left = "(" if low_open or low is None else "["
        right = ")" if high_open or high is None else "]"
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        raise error(f"{name} must be in {left}{lo}, {hi}{right}, got {value!r}")
    return x


def check_choice(name: str, value: object, choices: Collection[object], *,
                 error: type[Exception] = ParameterError) -> object:
    """Return ``value`` if it is one of ``choices``; the message lists them."""
    if value not in choices:
        listed = ", ".join(repr(c) for c in choices)
        raise error(f"{name} must be one of {listed}, got {value!r}")
    return value
