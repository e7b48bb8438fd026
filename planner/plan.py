"""The result of the trajectory optimiser: a planned bucket path with what the CasADi model predicts."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, PlanningError
from wheelloader.estimator.checks import check_range

__all__ = ["Plan"]


@dataclass(frozen=True, eq=False)
class Plan:
    """A planned bucket path with what the CasADi model predicts along it.

    Attributes
    ----------
    t, x, z, blade_angle, fill : numpy.ndarray
        Node times [s] and states (N + 1 values).
    vx, vz, omega : numpy.ndarray
        Interval controls (N values) [m/s, m/s, rad/s].
    tangential, normal : numpy.ndarray
        Predicted F_T, F_N at the nodes [N] (node 0: at the start pose, empty of new soil).
    energy : float
        Predicted energy of the cycle [J].
    success : bool
        Whether IPOPT reported success.
    status : str
        IPOPT's return status.
    iterations : int
        IPOPT iterations.
    solve_time : float
        Wall time of the solver call [s].
    objective : float
        Final objective value.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    blade_angle: np.ndarray
    fill: np.ndarray
    vx: np.ndarray
    vz: np.ndarray
    omega: np.ndarray
    tangential: np.ndarray
    normal: np.ndarray
    energy: float
    success: bool
    status: str
    iterations: int
    solve_time: float
    objective: float
    raw: dict[str, Any] = field(default_factory=dict, repr=False)

    @property
    def duration(self) -> float:
        """Planned duration [s]."""
        return float(self.t[-1] - self.t[0])

    @property
    def final_fill(self) -> float:
        """Predicted fill at the end [m^3]."""
        return float(self.fill[-1])

    def path(self, rate: float = 60.0, name: str = "planned") -> BucketPath:
        """The plan sampled at ``rate`` [Hz] (linear between nodes: the controls are piecewise constant)."""
        check_range("rate", rate, 0.0, None, low_open=True, error=PlanningError)  # Hz
        count = int(math.floor(self.duration * rate + 1e-9)) + 1
        t = self.t[0] + np.arange(count) / rate
        if t[-1] < self.t[-1] - 1e-9:
            t = np.append(t, self.t[-1])
        return BucketPath(t - self.t[0], np.interp(t, self.t, self.x), np.interp(t, self.t, self.z),
                          np.interp(t, self.t, self.blade_angle), name)
