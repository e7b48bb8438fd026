"""Fit only what the cycles can identify: :class:`HeldPrior`, the setting ``CalibrationOptions(held=...)``.

A cycle's forces pin down few of the seven fit-vector parameters (Sobol indices,
:mod:`~wheelloader.estimator.calibration.sensitivity`). Fitted freely, the others absorb the misfit of the
ones that matter and land where they do not carry over to another path: a shallow cycle pushes ``n`` to
its bound and ``phi`` far below the soil's. A :class:`HeldPrior` names the parameters fitted from one
cycle and those fitted from two or more; every other parameter is held at its prior mean (``std`` 0) or
near it (a Gaussian prior of width ``std``, the MAP estimate of the varpro method). Means and widths are
meant to be learned from data the prediction does not see (``benchmarks/transfer.py`` learns them from the
training split of the continuum data).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import CalibrationError
from ..soil_vector import SOIL_VECTOR_NAMES

__all__ = ["HeldPrior"]


def _names(field: str, names: Any) -> tuple[str, ...]:
    try:
        out = tuple(str(n) for n in names)
    except TypeError:
        raise CalibrationError(f"held: {field} must be a sequence of parameter names, got {names!r}") from None
    bad = [n for n in out if n not in SOIL_VECTOR_NAMES]
    if bad:
        raise CalibrationError(f"held: {field} has unknown parameter(s) {bad}; expected some of "
                               f"{list(SOIL_VECTOR_NAMES)}")
    return tuple(n for n in SOIL_VECTOR_NAMES if n in out)


@dataclass(frozen=True)
class HeldPrior:
    """Which fit-vector parameters a calibration fits, and the prior the others are held at.

    Parameters
    ----------
    mean : dict
        ``{fit-vector name: prior mean}`` (SI; angles in rad; ``K`` = k_c / b + k_phi) of every parameter that
        may be held (those not free for some cycle count).
    std : dict, optional
        ``{name: prior standard deviation}``; 0 or absent: held fixed at the mean; > 0: a Gaussian prior
        (MAP estimate, varpro method).
    free_one : sequence of str
        Parameters fitted freely from one cycle.
    free_several : sequence of str, optional
        Parameters fitted freely from two or more cycles (default ``free_one``).

    Raises
    ------
    CalibrationError
        On an unknown name, a held parameter without a mean, a mean or width that is not finite, a width < 0.
    """

    mean: dict[str, float]
    std: dict[str, float] | None = None
    free_one: tuple[str, ...] = ()
    free_several: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "free_one", _names("free_one", self.free_one))
        set_(self, "free_several", self.free_one if self.free_several is None
             else _names("free_several", self.free_several))
        for field in ("mean", "std"):
            value = getattr(self, field)
            if value is None:
                continue
            if not isinstance(value, dict):
                raise CalibrationError(f"held: {field} must be a dict {{name: value}}, got {type(value).__name__}")
            _names(field, value)
            try:
                clean = {n: float(v) for n, v in value.items()}
            except (TypeError, ValueError):
                raise CalibrationError(f"held: {field} values must be numbers, got {value!r}") from None
            if not all(math.isfinite(v) and (field == "mean" or v >= 0.0) for v in clean.values()):
                raise CalibrationError(f"held: {field} values must be finite{' and >= 0' * (field == 'std')}, "
                                       f"got {value!r}")
            set_(self, field, clean)
        missing = [n for n in SOIL_VECTOR_NAMES if n not in self.free_one or n not in self.free_several]
        missing = [n for n in missing if n not in self.mean]
        if missing:
            raise CalibrationError(f"held: no prior mean for the held parameter(s) {missing}")

    def free(self, cycles: int) -> tuple[str, ...]:
        """The parameters fitted freely from ``cycles`` cycles."""
        return self.free_one if cycles <= 1 else self.free_several

    def apply(self, cycles: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                          tuple[np.ndarray, np.ndarray] | None]:
        """Fit-vector bounds with the fixed parameters pinned, and the Gaussian prior's ``(mean, std)`` or None.

        A held mean outside the calibration's bounds is clipped into them.
        """
        lo, hi = lo.copy(), hi.copy()
        mean, std = np.zeros(lo.size), np.zeros(lo.size)
        free = self.free(cycles)
        for i, name in enumerate(SOIL_VECTOR_NAMES):
            if name in free:
                continue
            m = float(np.clip(self.mean[name], lo[i], hi[i]))
            s = (self.std or {}).get(name, 0.0)
            if s > 0.0:
                mean[i], std[i] = m, s
            else:
                lo[i] = hi[i] = m
        return lo, hi, ((mean, std) if np.any(std > 0.0) else None)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping (:meth:`from_dict` inverts it)."""
        return {"mean": dict(self.mean), "std": None if self.std is None else dict(self.std),
                "free_one": list(self.free_one), "free_several": list(self.free_several)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> HeldPrior:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(data["mean"], data.get("std"), tuple(data.get("free_one", ())), data.get("free_several"))
        except (KeyError, TypeError) as exc:
            raise CalibrationError(f"held: {exc}") from None
