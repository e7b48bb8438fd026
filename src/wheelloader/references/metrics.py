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


def lifted_work(energy_j: float, fill_m3: float, log: CycleLog, z_ref: float, soil: str) -> float:
    """A cycle's energy with its kept load lifted from the path's end height to ``z_ref`` [J] (credited where the
    path ends above it): ``energy_j + rho g V (z_ref - z_end)``; density the continuum's where the log records one
    (the MPM plant's ``metadata["continuum"]``), else the soil preset's ``gamma`` [kg/m^3]."""
    from wheelloader.estimator import preset
    from wheelloader.estimator.force_model import GRAVITY

    density = float((log.metadata.get("continuum") or {}).get("density") or preset(soil).gamma)
    return energy_j + density * GRAVITY * fill_m3 * (z_ref - float(log.path.z[-1]))


def above_loader_limits(log: CycleLog) -> bool:
    """Whether a raw sample of the plant's force exceeded the loader's limits (F_T above ``Loader().max_push_force``
    or F_N above ``max_lift_force``, the env's stall rule): the loader would have stalled there."""
    from wheelloader.estimator import Loader

    loader = Loader()
    return bool(max(float(np.max(log.tangential)), 0.0) > loader.max_push_force
                or float(np.max(log.normal)) > loader.max_lift_force)
