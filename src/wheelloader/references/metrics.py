"""What a plant's cycle cost and gave, from its log alone (the same measurement for every strategy)."""

from __future__ import annotations

import numpy as np

from wheelloader.estimator import CycleLog


def blade_frame(fx: np.ndarray, fz: np.ndarray, blade_angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The references' blade-frame forces ``(F_T, F_N)`` of a world-frame force ``(F_x, F_z)`` on the bucket:
    ``F_T = -(F_x cos a + F_z sin a)``, ``F_N = F_x sin a - F_z cos a`` with ``a`` the blade angle."""
    a = np.asarray(blade_angle, dtype=float)
    return -(fx * np.cos(a) + fz * np.sin(a)), fx * np.sin(a) - fz * np.cos(a)


def world_force(log: CycleLog) -> tuple[np.ndarray, np.ndarray]:
    """The soil's force on the bucket in the world frame ``(F_x, F_z)`` [N] from the log's F_T, F_N.

    The inverse of :func:`blade_frame` (the references' convention; see the MPM README).
    """
    a = np.asarray(log.path.blade_angle, dtype=float)
    t, n = np.asarray(log.tangential, dtype=float), np.asarray(log.normal, dtype=float)
    return -t * np.cos(a) + n * np.sin(a), -t * np.sin(a) - n * np.cos(a)


def cycle_work(log: CycleLog) -> float:
    """Work the bucket did on the soil along the logged path [J]: ``-integral F . v dt`` (trapezoid rule).

    ``F`` is the soil's force on the bucket (:func:`world_force`), ``v`` the tip velocity of the path; the
    weight of the carried soil is part of ``F``, so lifting it counts. Rotation work is not included (the
    logs carry no torque).
    """
    fx, fz = world_force(log)
    t = np.asarray(log.path.t, dtype=float)
    vx = np.gradient(np.asarray(log.path.x, dtype=float), t)
    vz = np.gradient(np.asarray(log.path.z, dtype=float), t)
    power = -(fx * vx + fz * vz)
    return float(np.sum(0.5 * (power[1:] + power[:-1]) * np.diff(t)))
