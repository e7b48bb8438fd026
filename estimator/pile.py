"""Pile surface profile z_s(x) and carving by a bucket path.

The pile is quasi-2D: a surface height ``z_s(x)`` [m] over a horizontal
coordinate ``x`` [m], extruded over the bucket width. The digging direction
is +x: the pile rises in +x from its toe. The surface is stored on a uniform
grid and is linear between nodes; outside the grid it is extended with the
end heights. Volumes are cross-section areas [m^2] times the bucket width.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from .checks import check_finite, check_range
from .errors import ParameterError

#: Default grid spacing of a pile surface [m].
DEFAULT_SPACING = 0.002


def _as_1d_finite(name: str, values: object) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a sequence of numbers") from None
    if arr.ndim != 1:
        raise ParameterError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name} contains NaN or infinite values")
    return arr


def node_height(nodes: list[float], x0: float, spacing: float, x: float) -> float:
    """Height at ``x`` of the polyline through ``nodes`` (a list) on the grid ``x0 + k * spacing`` [m]: linear
    between nodes, constant outside the grid. The one scalar interpolation of :meth:`Pile.height_at`,
    :meth:`SurfaceCarver.height_at` and the env's look-ahead observation."""
    u = (x - x0) / spacing
    if u <= 0.0:
        return nodes[0]
    last = len(nodes) - 1
    if u >= last:
        return nodes[last]
    i = int(u)
    a = nodes[i]
    return a + (u - i) * (nodes[i + 1] - a)


def node_heights(nodes: list[float], x0: float, spacing: float, x: float, offsets: Sequence[float],
                 base: float = 0.0) -> list[float]:
    """:func:`node_height` at ``x + offset`` for each of ``offsets``, minus ``base`` (one call for a few points:
    the env's look-ahead observation, the surface ahead of the tip relative to the tip)."""
    last = len(nodes) - 1
    out = []
    for dx in offsets:
        u = (x + dx - x0) / spacing
        if u <= 0.0:
            out.append(nodes[0] - base)
        elif u >= last:
            out.append(nodes[last] - base)
        else:
            i = int(u)
            a = nodes[i]
            out.append(a + (u - i) * (nodes[i + 1] - a) - base)
    return out


@dataclass(frozen=True, eq=False)
class Pile:
    """A pile surface on a uniform grid.

    Use :meth:`ideal_slope`, :meth:`trapezoid` or :meth:`from_polyline` to
    build one. Instances are immutable; carving returns a new pile.

    Parameters
    ----------
    x0 : float
        x of the first grid node [m].
    spacing : float
        Grid spacing [m].
    heights : array_like
        Surface height z_s at each node [m] (z up).
    """

    x0: float
    spacing: float
    heights: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        check_finite("Pile.x0", self.x0)
        check_range("Pile.spacing", self.spacing, 0.0, None, low_open=True)
        z = _as_1d_finite("Pile.heights", self.heights).copy()
        if z.size < 2:
            raise ParameterError("Pile.heights needs at least 2 nodes")
        z.flags.writeable = False
        object.__setattr__(self, "x0", float(self.x0))
        object.__setattr__(self, "spacing", float(self.spacing))
        object.__setattr__(self, "heights", z)

    # ------------------------------------------------------------ builders
    @classmethod
    def from_polyline(cls, x: object, z: object, spacing: float = DEFAULT_SPACING) -> Pile:
        """Resample a polyline surface (x strictly increasing) onto a uniform grid."""
        xs = _as_1d_finite("pile x", x)
        zs = _as_1d_finite("pile z", z)
        if xs.size != zs.size:
            raise ParameterError(f"pile x and z differ in length: {xs.size} vs {zs.size}")
        if xs.size < 2:
            raise ParameterError("a pile polyline needs at least 2 points")
        if np.any(np.diff(xs) <= 0.0):
            raise ParameterError("pile polyline x must be strictly increasing")
        check_range("spacing", spacing, 0.0, None, low_open=True)  # m
        count = int(math.ceil((xs[-1] - xs[0]) / spacing - 1e-9)) + 1
        grid = xs[0] + spacing * np.arange(count)
        return cls(float(xs[0]), float(spacing), np.interp(grid, xs, zs))

    @classmethod
    def ideal_slope(
        cls,
        angle: float = math.radians(30.0),
        toe_x: float = 0.0,
        length: float = 4.0,
        ground_before: float = 0.5,
        spacing: float = DEFAULT_SPACING,
    ) -> Pile:
        """An ideal slope of ``angle`` [rad] rising in +x from ``toe_x`` [m], on flat ground z = 0.

        The slope extends ``length`` m beyond the toe; ``ground_before`` m of
        flat ground lie in front of it.
        """
        _check_angle("angle", angle)
        check_range("length", length, 0.0, None, low_open=True)  # m
        check_range("ground_before", ground_before, 0.0, None)
        xs = [toe_x - ground_before, toe_x, toe_x + length]
        zs = [0.0, 0.0, length * math.tan(angle)]
        if ground_before == 0.0:
            xs, zs = xs[1:], zs[1:]
        return cls.from_polyline(xs, zs, spacing)

    @classmethod
    def trapezoid(
        cls,
        angle: float = math.radians(30.0),
        height: float = 1.0,
        top_length: float = 1.5,
        toe_x: float = 0.0,
        back_angle: float | None = None,
        ground_before: float = 0.5,
        spacing: float = DEFAULT_SPACING,
    ) -> Pile:
        """A trapezoidal pile: front slope ``angle``, flat top, back slope, on ground z = 0."""
        _check_angle("angle", angle)
        back = angle if back_angle is None else back_angle
        _check_angle("back_angle", back)
        check_range("height", height, 0.0, None, low_open=True)  # m
        check_range("top_length", top_length, 0.0, None)
        check_range("ground_before", ground_before, 0.0, None)
        front = height / math.tan(angle)
        rear = height / math.tan(back)
        xs = [toe_x - ground_before, toe_x, toe_x + front, toe_x + front + top_length,
              toe_x + front + top_length + rear, toe_x + front + top_length + rear + 0.5]
        zs = [0.0, 0.0, height, height, 0.0, 0.0]
        if ground_before == 0.0:
            xs, zs = xs[1:], zs[1:]
        if top_length == 0.0:
            del xs[2], zs[2]
        return cls.from_polyline(xs, zs, spacing)

    # ------------------------------------------------------------- queries
    @property
    def x(self) -> np.ndarray:
        """Grid node positions [m]."""
        return self.x0 + self.spacing * np.arange(self.heights.size)

    @property
    def x_end(self) -> float:
        """x of the last node [m]."""
        return self.x0 + self.spacing * (self.heights.size - 1)

    def surface_height(self, x: float | np.ndarray) -> float | np.ndarray:
        """Surface height z_s(x) [m], linear between nodes, constant outside the grid."""
        if type(x) is float or np.ndim(x) == 0:
            return self.height_at(float(x))
        return np.interp(np.asarray(x, dtype=float), self.x, self.heights)

    @functools.cached_property
    def nodes(self) -> list[float]:
        """The heights as a Python list (read-only by convention, like :attr:`heights`): the scalar paths
        index it, which is several times cheaper than indexing the array."""
        return self.heights.tolist()

    def height_at(self, x: float) -> float:
        """Surface height at one scalar ``x`` [m]: the fast path of :meth:`surface_height` (no NumPy call)."""
        return node_height(self.nodes, self.x0, self.spacing, x)

    def slope_angle(self, x: float | np.ndarray, window: float = 0.1) -> float | np.ndarray:
        """Local surface slope alpha [rad] at ``x``: the chord slope over ``x +- window``.

        The chord makes alpha continuous in x even where the polyline has
        kinks (toe, crest, carved edges).
        """
        if type(x) is float or np.ndim(x) == 0:
            x, z, x0, sp = float(x), self.nodes, self.x0, self.spacing
            return math.atan((node_height(z, x0, sp, x + window) - node_height(z, x0, sp, x - window))
                             / (2.0 * window))
        x = np.asarray(x, dtype=float)
        rise = self.surface_height(x + window) - self.surface_height(x - window)
        return np.arctan(rise / (2.0 * window))

    def area(self, base: float = 0.0) -> float:
        """Cross-section area between the surface and z = ``base`` [m^2] (trapezoid rule)."""
        h = self.heights - base
        return float(self.spacing * (h.sum() - 0.5 * (h[0] + h[-1])))

    def volume(self, width: float, base: float = 0.0) -> float:
        """Soil volume over ``width`` [m^3]."""
        return self.area(base) * width

    def with_heights(self, heights: np.ndarray) -> Pile:
        """A pile on the same grid with new heights."""
        return Pile(self.x0, self.spacing, heights)

    def relaxed(self, repose_angle: float, iterations: int = 100_000, tolerance: float = 1e-9) -> Pile:
        """Let slopes steeper than ``repose_angle`` [rad] slump, conserving area exactly.

        A sand-pile relaxation: wherever two neighbouring nodes differ in
        height by more than ``spacing * tan(repose_angle)``, soil moves from
        the higher to the lower node until the pair sits at the limit. Pairs
        are updated in two alternating sweeps (even, then odd pairs) so no
        node takes part in two moves at once. Every move conserves the
        trapezoid-rule area; the two end nodes are held fixed. Stops when no
        slope exceeds the limit by more than ``tolerance`` (in height per
        node) or after ``iterations`` sweep pairs.
        """
        _check_angle("repose_angle", repose_angle)
        z = self.heights.copy()
        limit = self.spacing * math.tan(repose_angle)
        last_pair = z.size - 2
        # pairs (i, i+1) for i = first, first+2, ... (pairs touching the ends excluded), as views of z: the
        # lower and upper nodes of the even pairs, then of the odd ones
        sweeps = [(z[first:last_pair:2], z[first + 1:last_pair + 1:2]) for first in (1, 2) if first < last_pair]
        for _ in range(int(iterations)):
            moved = False
            for lower, upper in sweeps:
                diff = upper - lower
                excess = np.abs(diff) - limit
                mask = excess > tolerance
                if not mask.any():
                    continue
                moved = True
                move = np.where(mask, 0.5 * excess * np.sign(diff), 0.0)
                upper -= move
                lower += move
            if not moved:
                break
        return self.with_heights(z)

    def to_dict(self) -> dict[str, object]:
        """JSON-serialisable polyline form: {"x": [...], "z": [...], "spacing": dx} with the grid nodes."""
        return {"x": self.x.tolist(), "z": self.heights.tolist(), "spacing": self.spacing}

    @classmethod
    def from_dict(cls, data: dict[str, object], spacing: float | None = None) -> Pile:
        """Inverse of :meth:`to_dict` (any polyline; resampled at ``spacing``, else the stored spacing)."""
        if not isinstance(data, dict) or "x" not in data or "z" not in data:
            raise ParameterError('a pile must be a mapping with "x" and "z" lists')
        xs = _as_1d_finite("pile x", data["x"])
        if spacing is None and data.get("spacing") is not None:
            spacing = float(data["spacing"])
        if spacing is None:
            steps = np.diff(xs)
            spacing = float(np.median(steps)) if steps.size else DEFAULT_SPACING
        return cls.from_polyline(xs, data["z"], spacing)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Pile):
            return NotImplemented
        return (self.x0 == other.x0 and self.spacing == other.spacing
                and self.heights.shape == other.heights.shape and bool(np.all(self.heights == other.heights)))

    __hash__ = None  # type: ignore[assignment]

    # ------------------------------------------------------------- carving
    def carve(self, x: object, z: object, width: float, capacity: float, initial_fill: float = 0.0) -> CarveResult:
        """Carve the surface along a bucket-tip path and book the removed soil.

        Soil between the surface and the tip path (the lower envelope of the
        path, linear between samples) leaves the pile. It goes into the
        bucket until ``capacity`` [m^3] is reached; the rest spills (counted,
        not redeposited). The balance ``removed = in_bucket_gain + spilled``
        holds by construction to rounding.

        Parameters
        ----------
        x, z : array_like
            Tip path samples [m].
        width : float
            Bucket width [m] (volume = area x width).
        capacity : float
            Bucket capacity [m^3].
        initial_fill : float
            Soil already in the bucket [m^3].

        Returns
        -------
        CarveResult
        """
        xs = _as_1d_finite("path x", x)
        zs = _as_1d_finite("path z", z)
        if xs.size != zs.size or xs.size < 1:
            raise ParameterError("path x and z must be non-empty and of equal length")
        if not (width > 0 and capacity > 0 and 0.0 <= initial_fill <= capacity * (1 + 1e-12)):
            raise ParameterError("need width > 0, capacity > 0 and 0 <= initial_fill <= capacity")
        carver = SurfaceCarver(self, width, capacity, initial_fill)
        removed_per_sample = np.zeros(xs.size)
        for i in range(1, xs.size):
            removed_per_sample[i] = carver.cut_segment(xs[i - 1], zs[i - 1], xs[i], zs[i])
        return carver.result(np.cumsum(removed_per_sample))


def _check_angle(name: str, value: float) -> None:
    if not 0.0 < check_finite(name, value) < math.pi / 2:
        hint = " (angles are in radians)" if value >= math.pi / 2 else ""
        raise ParameterError(f"{name} must be in (0, pi/2) rad, got {value!r}{hint}")


@dataclass(frozen=True, eq=False)
class CarveResult:
    """Outcome of carving a pile along a path.

    Attributes
    ----------
    pile : Pile
        The surface after the path has passed.
    removed : float
        Volume that left the pile [m^3].
    in_bucket : float
        Volume in the bucket at the end [m^3] (includes ``initial_fill``).
    spilled : float
        Volume that did not fit in the bucket [m^3].
    initial_fill : float
        Volume in the bucket before the path [m^3].
    removed_history : numpy.ndarray
        Cumulative removed volume at each path sample [m^3].
    fill_history : numpy.ndarray
        Bucket fill at each path sample [m^3].
    """

    pile: Pile
    removed: float
    in_bucket: float
    spilled: float
    initial_fill: float
    removed_history: np.ndarray = field(repr=False)
    fill_history: np.ndarray = field(repr=False)

    @property
    def balance_error(self) -> float:
        """``removed - (in_bucket - initial_fill) - spilled`` [m^3]; zero up to rounding."""
        return self.removed - (self.in_bucket - self.initial_fill) - self.spilled


class SurfaceCarver:
    """Incremental carving of a pile, one tip segment at a time (used by the env).

    Keeps a mutable copy of the heights (a Python list: the carve touches a few nodes per call, and list
    items are several times cheaper to read and write than array items), the fill and the spill. Each call
    to :meth:`cut_segment` lowers the nodes under the segment to the segment's height and returns the volume
    removed [m^3].
    """

    __slots__ = ("x0", "spacing", "nodes", "width", "capacity", "fill", "spilled", "removed", "initial_fill",
                 "_last", "_template")

    def __init__(self, pile: Pile, width: float, capacity: float, initial_fill: float = 0.0) -> None:
        self._template = pile
        self.x0 = pile.x0
        self.spacing = pile.spacing
        self.nodes: list[float] = pile.heights.tolist()
        self._last = len(self.nodes) - 1
        self.width = float(width)
        self.capacity = float(capacity)
        self.initial_fill = float(initial_fill)
        self.fill = float(initial_fill)
        self.spilled = 0.0
        self.removed = 0.0

    @property
    def heights(self) -> np.ndarray:
        """The carved heights as a new array [m]."""
        return np.array(self.nodes)

    def height_at(self, x: float) -> float:
        """Carved surface height at one scalar ``x`` [m] (as :meth:`Pile.height_at`)."""
        return node_height(self.nodes, self.x0, self.spacing, x)

    def cut_segment(self, xa: float, za: float, xb: float, zb: float, changes: list | None = None) -> float:
        """Carve under the segment (xa, za)-(xb, zb); return the volume removed [m^3].

        ``changes``: a list that gets ``(node, old height)`` of every node lowered (for :meth:`restore`).
        """
        lo, hi = (xa, xb) if xa <= xb else (xb, xa)
        x0, sp, last = self.x0, self.spacing, self._last
        i0 = max(0, int(math.ceil((lo - x0) / sp - 1e-12)))
        i1 = min(last, int(math.floor((hi - x0) / sp + 1e-12)))
        if i1 < i0:
            return 0.0
        heights = self.nodes
        dx = xb - xa
        # Clearly above: nothing to cut. The margin covers the rounding of the interpolated heights below, and the
        # node-index tolerance (1e-12 spacings) lets a node sit just outside the segment, where the interpolation
        # extrapolates by |dz| * that offset / |dx|: the shortcut is taken only where that stays inside the margin
        # (a near-vertical segment, dx -> 0 but not 0, goes through the loop), so the result is always the same.
        if (abs(zb - za) * (1e-12 * sp + 1e-14) <= 5e-10 * abs(dx)
                and (za if za <= zb else zb) > max(heights[i0:i1 + 1]) + 1e-9):
            return 0.0
        removed_area = 0.0
        for i in range(i0, i1 + 1):
            zc = min(za, zb) if dx == 0.0 else za + (zb - za) * ((x0 + i * sp) - xa) / dx
            old = heights[i]
            if zc < old:
                heights[i] = zc
                removed_area += (0.5 * sp if i == 0 or i == last else sp) * (old - zc)  # trapezoid weight
                if changes is not None:
                    changes.append((i, old))
        removed = removed_area * self.width
        if removed > 0.0:
            self.removed += removed
            room = max(0.0, self.capacity - self.fill)
            taken = removed if removed <= room else room
            self.fill += taken
            self.spilled += removed - taken
        return removed

    def state(self) -> tuple[float, float, float]:
        """``(fill, spilled, removed)``: with the ``changes`` of :meth:`cut_segment`, what :meth:`restore` needs."""
        return self.fill, self.spilled, self.removed

    def restore(self, changes: list, state: tuple[float, float, float]) -> None:
        """Undo the cuts that filled ``changes`` since :meth:`state` gave ``state``."""
        heights = self.nodes
        for i, old in reversed(changes):
            heights[i] = old
        self.fill, self.spilled, self.removed = state

    def pile(self) -> Pile:
        """The carved surface as a new :class:`Pile`."""
        return self._template.with_heights(np.array(self.nodes))

    def result(self, removed_history: np.ndarray) -> CarveResult:
        """Summarise into a :class:`CarveResult`."""
        fill_history = np.minimum(self.initial_fill + removed_history, self.capacity)
        fill_history = np.maximum(fill_history, self.initial_fill)
        return CarveResult(self.pile(), self.removed, self.fill, self.spilled, self.initial_fill,
                           removed_history, fill_history)
