"""The rigid kinematic tool: oriented plates in a body frame, its pose along a path, and its outline.

Body frame: origin at the tool's reference point (the bucket's cutting-edge tip), ``u`` along the floor
from its back edge toward the tip, ``w`` along the floor's upper normal. A pose ``(x, z, a)`` puts the
origin at (x, z) and turns the frame by the blade angle ``a`` [rad]: ``e = (cos a, sin a)``,
``n = (-sin a, cos a)``. This is the convention of :class:`~wheelloader.estimator.BucketPath` and
``references/dem/yade_scenario.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wheelloader.estimator import Bucket, BucketPath

#: Back-plate height / floor length of the MPM bucket (the DEM scenario: 0.27 / 0.27).
BACK_PLATE_RATIO = 1.0
#: Top-plate length / floor length (the DEM scenario: 0.09 / 0.27).
TOP_PLATE_RATIO = 1.0 / 3.0


@dataclass(frozen=True)
class Plate:
    """A straight plate from ``start`` to ``end`` in the body frame (u, w) [m]."""

    start: tuple[float, float]
    end: tuple[float, float]

    def __post_init__(self) -> None:
        if math.dist(self.start, self.end) <= 0.0:
            raise ValueError(f"a plate needs two distinct end points, got {self.start} and {self.end}")


@dataclass(frozen=True)
class ToolShape:
    """Plates of a rigid tool and, for a bucket, the outline that holds soil.

    Attributes
    ----------
    plates : tuple of Plate
        The plates (at most :data:`MAX_PLATES`).
    outline : numpy.ndarray or None
        Closed polygon (k, 2) in the body frame whose inside counts as bucket fill, or None.
    """

    plates: tuple[Plate, ...]
    outline: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not 1 <= len(self.plates) <= MAX_PLATES:
            raise ValueError(f"a tool needs 1 to {MAX_PLATES} plates, got {len(self.plates)}")

    def world_points(self, pose: tuple[float, float, float], points: np.ndarray) -> np.ndarray:
        """Body-frame points (k, 2) in world coordinates at ``pose`` = (x, z, angle)."""
        x, z, a = pose
        e = np.array([math.cos(a), math.sin(a)])
        n = np.array([-math.sin(a), math.cos(a)])
        pts = np.asarray(points, dtype=float)
        return np.array([x, z]) + pts[:, :1] * e + pts[:, 1:2] * n

    def to_body(self, pose: tuple[float, float, float], xz: np.ndarray) -> np.ndarray:
        """World points (k, 2) in the body frame at ``pose``."""
        x, z, a = pose
        d = np.asarray(xz, dtype=float) - np.array([x, z])
        c, s = math.cos(a), math.sin(a)
        return np.column_stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c])

    def inside(self, pose: tuple[float, float, float], xz: np.ndarray) -> np.ndarray:
        """Boolean mask of the world points inside the outline (all False without an outline)."""
        if self.outline is None:
            return np.zeros(len(xz), dtype=bool)
        return points_in_polygon(self.to_body(pose, xz), self.outline)

    def extent(self, poses: np.ndarray) -> tuple[float, float, float, float]:
        """Bounding box (x_min, z_min, x_max, z_max) [m] of all plate end points over ``poses`` (k, 3)."""
        ends = np.array([p for plate in self.plates for p in (plate.start, plate.end)])
        pts = np.concatenate([self.world_points(tuple(pose), ends) for pose in np.asarray(poses, dtype=float)])
        return float(pts[:, 0].min()), float(pts[:, 1].min()), float(pts[:, 0].max()), float(pts[:, 1].max())


#: Most plates a tool may have (the solver's fixed table size).
MAX_PLATES = 4


def bucket_shape(bucket: Bucket | None = None) -> ToolShape:
    """The project's bucket as three plates: floor (back edge to tip), back plate, top plate.

    Floor = ``bucket.floor_length`` L ending at the tip (body origin); back plate normal to the floor,
    ``BACK_PLATE_RATIO * L`` high; top plate from the back plate's top toward the tip,
    ``TOP_PLATE_RATIO * L`` long (the proportions of ``references/dem/yade_scenario.py``). The fill outline is
    tip, back edge, back-plate top, top-plate end, closed by the strike line back to the tip.
    """
    bucket = bucket or Bucket()
    length = bucket.floor_length
    height = BACK_PLATE_RATIO * length
    top = TOP_PLATE_RATIO * length
    tip, back, back_top, top_end = (0.0, 0.0), (-length, 0.0), (-length, height), (-length + top, height)
    plates = (Plate(back, tip), Plate(back, back_top), Plate(back_top, top_end))
    return ToolShape(plates, np.array([tip, back, back_top, top_end]))


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule: which of ``points`` (k, 2) lie inside the closed ``polygon`` (m, 2)."""
    x, z = points[:, 0], points[:, 1]
    inside = np.zeros(len(points), dtype=bool)
    m = len(polygon)
    for i in range(m):
        x0, z0 = polygon[i]
        x1, z1 = polygon[(i + 1) % m]
        crosses = (z0 > z) != (z1 > z)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = x0 + (z - z0) * (x1 - x0) / (z1 - z0)
        inside ^= crosses & (x < x_cross)
    return inside


class Trajectory:
    """Pose of the tool at any time: linear interpolation of a path's samples.

    Before the first sample the tool rests at the first pose, after the last at the last pose.
    """

    def __init__(self, t: np.ndarray, x: np.ndarray, z: np.ndarray, angle: np.ndarray) -> None:
        self.t = np.asarray(t, dtype=float)
        self.x = np.asarray(x, dtype=float)
        self.z = np.asarray(z, dtype=float)
        self.angle = np.asarray(angle, dtype=float)
        if not (self.t.ndim == 1 and self.t.size >= 2 and np.all(np.diff(self.t) > 0)):
            raise ValueError("trajectory times must be a strictly increasing 1-D array of >= 2 samples")
        for name in ("x", "z", "angle"):
            if getattr(self, name).shape != self.t.shape:
                raise ValueError(f"trajectory {name} must have one value per time sample")

    @classmethod
    def from_path(cls, path: BucketPath) -> Trajectory:
        """The tip pose (x, z, blade angle) of a :class:`BucketPath`."""
        return cls(path.t, path.x, path.z, path.blade_angle)

    def pose(self, time: float) -> tuple[float, float, float]:
        """(x, z, angle) at ``time`` [s]."""
        return (float(np.interp(time, self.t, self.x)), float(np.interp(time, self.t, self.z)),
                float(np.interp(time, self.t, self.angle)))

    def poses(self) -> np.ndarray:
        """All sample poses (k, 3)."""
        return np.column_stack([self.x, self.z, self.angle])
