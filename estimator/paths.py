"""Bucket-tip paths: quadratic Bezier paths like the paper's Fig. 8.

A :class:`BucketPath` is a time series of the tip position (x, z) [m] and the
blade angle [rad] (sign convention in :mod:`wheelloader.estimator.kinematics`),
sampled at a fixed rate (60 Hz by default, as the paper's data).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .checks import check_range
from .errors import ParameterError

#: Default sampling rate [Hz] (the paper's data: 281 samples over 4.67 s).
DEFAULT_RATE = 60.0
#: Default cycle duration [s] (paper Section IV-A).
DEFAULT_DURATION = 4.67


@dataclass(frozen=True, eq=False)
class BucketPath:
    """A sampled bucket-tip path.

    Attributes
    ----------
    t : numpy.ndarray
        Time [s], strictly increasing.
    x, z : numpy.ndarray
        Tip position [m].
    blade_angle : numpy.ndarray
        Blade angle above +x [rad] (tip-down negative).
    name : str
        Label for plots and tables.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    blade_angle: np.ndarray
    name: str = field(default="path")

    def __post_init__(self) -> None:
        arrays = {}
        for key in ("t", "x", "z", "blade_angle"):
            arr = np.array(getattr(self, key), dtype=float)
            if arr.ndim != 1:
                raise ParameterError(f"BucketPath.{key} must be one-dimensional")
            if not np.all(np.isfinite(arr)):
                raise ParameterError(f"BucketPath.{key} contains NaN or infinite values")
            arr.flags.writeable = False
            arrays[key] = arr
        sizes = {arr.size for arr in arrays.values()}
        if len(sizes) != 1:
            raise ParameterError(f"BucketPath arrays differ in length: { {k: a.size for k, a in arrays.items()} }")
        if arrays["t"].size < 2:
            raise ParameterError("a BucketPath needs at least 2 samples")
        if np.any(np.diff(arrays["t"]) <= 0.0):
            raise ParameterError("BucketPath.t must be strictly increasing")
        for key, arr in arrays.items():
            object.__setattr__(self, key, arr)

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        """Last minus first time [s]."""
        return float(self.t[-1] - self.t[0])

    def velocity(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Finite-difference (x, z, blade-angle) rates per sample [m/s, m/s, rad/s]."""
        return (np.gradient(self.x, self.t), np.gradient(self.z, self.t), np.gradient(self.blade_angle, self.t))

    def acceleration(self) -> tuple[np.ndarray, np.ndarray]:
        """Finite-difference tip acceleration ``(a_x, a_z)`` per sample [m/s^2] (gradient of :meth:`velocity`)."""
        if self.t.size < 3:
            zero = np.zeros_like(self.x)
            return zero, zero.copy()
        vx, vz, _ = self.velocity()
        return np.gradient(vx, self.t), np.gradient(vz, self.t)

    def resample(self, rate: float) -> BucketPath:
        """Linear resampling at ``rate`` [Hz] over the same time span."""
        check_range("rate", rate, 0.0, None, low_open=True)  # Hz
        count = int(math.floor(self.duration * rate + 1e-9)) + 1
        t = self.t[0] + np.arange(count) / rate
        return BucketPath(t, np.interp(t, self.t, self.x), np.interp(t, self.t, self.z),
                          np.interp(t, self.t, self.blade_angle), self.name)

    def shifted(self, dx: float = 0.0, dz: float = 0.0, name: str | None = None) -> BucketPath:
        """The same motion translated by (dx, dz) [m]."""
        return BucketPath(self.t, self.x + dx, self.z + dz, self.blade_angle, name or self.name)


def _smoothstep(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def blade_angle_profile(u: np.ndarray, start: float, end: float, curl_from: float = 0.55) -> np.ndarray:
    """Blade angle along the path parameter ``u`` in [0, 1]: ``start`` until ``curl_from``,
    then a smooth (C1) curl to ``end`` [rad]."""
    check_range("curl_from", curl_from, 0.0, 1.0, high_open=True)
    return start + (end - start) * _smoothstep((u - curl_from) / (1.0 - curl_from))


def bezier_path(
    start: tuple[float, float],
    control: tuple[float, float],
    end: tuple[float, float],
    *,
    duration: float = DEFAULT_DURATION,
    rate: float = DEFAULT_RATE,
    angle_start: float = math.radians(-5.0),
    angle_end: float = math.radians(45.0),
    curl_from: float = 0.55,
    name: str = "bezier",
) -> BucketPath:
    """Quadratic Bezier tip path ``B(u) = (1-u)^2 P0 + 2u(1-u) P1 + u^2 P2`` (Fig. 8).

    The parameter u advances uniformly in time over ``duration`` [s], sampled
    at ``rate`` [Hz]; the blade angle follows :func:`blade_angle_profile`.
    """
    check_range("duration", duration, 0.0, None, low_open=True)  # s
    check_range("rate", rate, 0.0, None, low_open=True)  # Hz
    p0, p1, p2 = (np.asarray(p, dtype=float) for p in (start, control, end))
    for label, p in (("start", p0), ("control", p1), ("end", p2)):
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise ParameterError(f"{label} must be a finite (x, z) pair, got {p!r}")
    count = int(round(duration * rate)) + 1
    t = np.arange(count) / rate
    u = t / t[-1]
    pts = ((1 - u) ** 2)[:, None] * p0 + (2 * u * (1 - u))[:, None] * p1 + (u**2)[:, None] * p2
    return BucketPath(t, pts[:, 0], pts[:, 1], blade_angle_profile(u, angle_start, angle_end, curl_from), name)


def polyline_path(
    points: list[tuple[float, float]],
    *,
    duration: float = DEFAULT_DURATION,
    rate: float = DEFAULT_RATE,
    angle_start: float = math.radians(-5.0),
    angle_end: float = math.radians(45.0),
    curl_from: float = 0.55,
    name: str = "segmented",
) -> BucketPath:
    """Segmented-linear tip path through ``points`` at constant speed (Fig. 8, path type 3)."""
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2 or not np.all(np.isfinite(pts)):
        raise ParameterError("points must be at least two finite (x, z) pairs")
    seg = np.hypot(*np.diff(pts, axis=0).T)
    if np.any(seg <= 0.0):
        raise ParameterError("consecutive points must differ")
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    count = int(round(duration * rate)) + 1
    t = np.arange(count) / rate
    u = t / t[-1]
    s = u * arc[-1]
    return BucketPath(t, np.interp(s, arc, pts[:, 0]), np.interp(s, arc, pts[:, 1]),
                      blade_angle_profile(u, angle_start, angle_end, curl_from), name)


def default_path(toe_x: float = 0.0, rate: float = DEFAULT_RATE) -> BucketPath:
    """The default digging path on the default pile (path 1 of :func:`paper_paths`)."""
    return paper_paths(toe_x, rate)[0]


def paper_paths(toe_x: float = 0.0, rate: float = DEFAULT_RATE) -> list[BucketPath]:
    """Four paths in the spirit of the paper's Fig. 8, for a pile whose toe is at ``toe_x``.

    1. the reference smooth Bezier path (training path);
    2. a path of different curvature (control point moved);
    3. the reference motion shifted in start and end point (same motion profile);
    4. a segmented-linear path through similar points.

    Tuned for the default 30 deg trapezoidal pile and the default bucket so
    that path 1 fills roughly the bucket's capacity.
    """
    p1 = bezier_path((toe_x - 0.10, 0.03), (toe_x + 1.20, 0.05), (toe_x + 1.45, 1.20), curl_from=0.6, rate=rate,
                     name="path 1")
    p2 = bezier_path((toe_x - 0.10, 0.03), (toe_x + 0.90, 0.00), (toe_x + 1.35, 1.20), curl_from=0.55, rate=rate,
                     angle_end=math.radians(50.0), name="path 2")
    p3 = p1.shifted(dx=0.10, dz=0.03, name="path 3")
    p4 = polyline_path([(toe_x - 0.10, 0.03), (toe_x + 1.00, 0.12), (toe_x + 1.45, 1.20)], curl_from=0.6, rate=rate,
                       name="path 4")
    return [p1, p2, p3, p4]
