"""Exceptions raised by wheelloader.

All user-facing errors derive from :class:`WheelloaderError` and from the
built-in exception that best describes them, so ``except ValueError`` keeps
working for callers that do not know this module.
"""

from __future__ import annotations


class WheelloaderError(Exception):
    """Base class of every error raised on purpose by wheelloader."""


class ParameterError(WheelloaderError, ValueError):
    """A parameter is outside its documented domain (bounds, sign, type)."""


class CycleLogError(WheelloaderError, ValueError):
    """A cycle log (CSV + JSON sidecar) is malformed or physically implausible."""


class CalibrationError(WheelloaderError, ValueError):
    """A calibration request cannot be carried out (bad data, bounds, method)."""


class PlanningError(WheelloaderError, RuntimeError):
    """A planning request cannot be carried out."""
