"""Scenes for the plant: soil particles under a pile surface on a bed, the domain around a tool's path.

Everything here is NumPy; nothing needs Taichi.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from wheelloader.estimator import Pile

from .solver import PARTICLES_PER_CELL, Domain
from .tool import ToolShape, Trajectory

#: Relative half-width of the uniform jitter of particle positions on their lattice.
DEFAULT_JITTER = 0.25


@dataclass(frozen=True)
class SceneSettings:
    """How much soil around the path is simulated [m].

    Parameters
    ----------
    bed_depth : float
        Soil bed below the lowest point of the pile surface and of the tool's path (the floor under the
        bed is sticky and rigid; it must not be felt by the cut). Default 0.2 m.
    wall_margin : float
        The pile is truncated by a frictionless vertical wall this far beyond the furthest tip position
        (as the DEM truncates its pile behind the dig region). Default 0.6 m.
    front_margin : float
        Soil kept in front of the tool's rearmost point at any pose. Default 0.1 m.
    top_margin : float
        Free space above the highest soil or tool point. Default 0.1 m.
    jitter : float
        Particles start on a lattice of spacing dx / 2, each moved by a uniform random offset of up to
        ``jitter`` times the spacing per axis (seeded). Default 0.25.
    order_seed : int or None
        None (default): the particles are stored in lattice order (column by column). An integer: in a
        random order drawn with this seed. The soil is the same; only the order in which the particle ->
        grid transfer adds the particles' contributions changes, so the forces change by rounding alone
        (for measuring a cycle's reproducibility, ``benchmarks/mpm_speed.py --perturb order``).
    ulp_seed : int or None
        None (default): no change. An integer: each particle coordinate, as the solver stores it (32-bit
        float), moved by -1, 0 or +1 unit in the last place (equally likely, drawn with this seed); the
        initial stress is unchanged. A last-bit perturbation like ``order_seed``.
    """

    bed_depth: float = 0.2
    wall_margin: float = 0.6
    front_margin: float = 0.1
    top_margin: float = 0.1
    jitter: float = DEFAULT_JITTER
    order_seed: int | None = None
    ulp_seed: int | None = None

    def __post_init__(self) -> None:
        for name in ("bed_depth", "wall_margin", "front_margin", "top_margin", "jitter"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f"SceneSettings.{name} must be a finite number >= 0, got {value!r}")
        if self.bed_depth <= 0.0:
            raise ValueError(f"SceneSettings.bed_depth must be > 0 m, got {self.bed_depth!r}")
        if self.jitter >= 0.5:
            raise ValueError(f"SceneSettings.jitter must be < 0.5 (particles would swap cells), got {self.jitter!r}")
        for name in ("order_seed", "ulp_seed"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                      or value < 0):
                raise ValueError(f"SceneSettings.{name} must be None or an integer >= 0, got {value!r}")

    def perturbations(self) -> dict[str, int]:
        """The last-bit perturbations that are set (``order_seed``, ``ulp_seed``), by name."""
        return {name: int(getattr(self, name)) for name in ("order_seed", "ulp_seed")
                if getattr(self, name) is not None}


@dataclass(frozen=True, eq=False)
class Scene:
    """Initial particles and the box that holds them and the tool.

    Attributes
    ----------
    domain : Domain
        Simulation box [m].
    particles : numpy.ndarray
        Particle positions (N, 2) [m].
    overburden : numpy.ndarray
        Depth of each particle below the pile surface [m] (for the geostatic start).
    soil_x : tuple of float
        x range [m] of simulated soil (front wall, back wall).
    spacing : float
        Particle lattice spacing [m].
    """

    domain: Domain
    particles: np.ndarray
    overburden: np.ndarray
    soil_x: tuple[float, float]
    spacing: float


def fill_particles(surface: Callable[[np.ndarray], np.ndarray], x_lo: float, x_hi: float, z_bed: float, spacing: float,
                   rng: np.random.Generator, jitter: float = DEFAULT_JITTER) -> tuple[np.ndarray, np.ndarray]:
    """Particles on a jittered lattice between ``z_bed`` and ``surface(x)`` for x in [x_lo, x_hi].

    Returns the positions (N, 2) and each particle's depth below the surface [m].
    """
    z_top = float(np.max(surface(np.linspace(x_lo, x_hi, 512))))
    xs = np.arange(x_lo + 0.5 * spacing, x_hi, spacing)
    zs = np.arange(z_bed + 0.5 * spacing, z_top, spacing)
    gx, gz = np.meshgrid(xs, zs, indexing="ij")
    pts = np.column_stack([gx.ravel(), gz.ravel()])
    pts += rng.uniform(-jitter, jitter, size=pts.shape) * spacing
    pts[:, 0] = np.clip(pts[:, 0], x_lo + 1e-6, x_hi - 1e-6)
    pts[:, 1] = np.maximum(pts[:, 1], z_bed + 1e-6)
    depth = surface(pts[:, 0]) - pts[:, 1]
    keep = depth > 0.0
    return pts[keep], depth[keep]


def bucket_scene(pile: Pile, trajectory: Trajectory, shape: ToolShape, dx: float, seed: int,
                 settings: SceneSettings | None = None) -> Scene:
    """The soil of ``pile`` around the tool's path, on a bed, truncated behind by a wall.

    Parameters
    ----------
    pile : Pile
        Start surface.
    trajectory : Trajectory
        The tool's poses (the domain covers every pose).
    shape : ToolShape
        The tool's plates.
    dx : float
        Grid cell size [m] (particles: ``PARTICLES_PER_CELL`` per cell and axis).
    seed : int
        Seed of the particle jitter.
    settings : SceneSettings
        Margins and bed depth.
    """
    settings = settings or SceneSettings()
    poses = trajectory.poses()
    tx_min, tz_min, tx_max, tz_max = shape.extent(poses)
    x_lo = tx_min - settings.front_margin
    x_hi = float(np.max(trajectory.x)) + settings.wall_margin
    grid = np.linspace(x_lo, x_hi, max(16, int((x_hi - x_lo) / 0.002)))
    heights = pile.surface_height(grid)
    z_bed = min(float(np.min(heights)), float(np.min(trajectory.z)), tz_min) - settings.bed_depth
    z_hi = max(float(np.max(heights)), tz_max) + settings.top_margin
    spacing = dx / PARTICLES_PER_CELL
    rng = np.random.default_rng(seed)
    pts, depth = fill_particles(pile.surface_height, x_lo, x_hi, z_bed, spacing, rng, settings.jitter)
    pts, depth = perturb_particles(pts, depth, settings.order_seed, settings.ulp_seed)
    return Scene(Domain(x_lo, z_bed, x_hi, z_hi), pts, depth, (x_lo, x_hi), spacing)


def perturb_particles(pts: np.ndarray, depth: np.ndarray, order_seed: int | None = None,
                      ulp_seed: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The particles (and their depths) reordered with ``order_seed`` and moved by one unit in the last place
    of a 32-bit float with ``ulp_seed`` (:class:`SceneSettings`); unchanged where a seed is None.

    Both change the forces by rounding only: the reordering keeps every position, the move keeps each
    coordinate within one unit of the float the solver would store anyway.
    """
    if order_seed is not None:
        order = np.random.default_rng(order_seed).permutation(len(pts))
        pts, depth = pts[order], depth[order]
    if ulp_seed is not None:
        stored = np.asarray(pts, dtype=np.float32)
        step = np.random.default_rng(ulp_seed).integers(-1, 2, size=stored.shape)
        moved = np.where(step > 0, np.nextafter(stored, np.float32(np.inf)),
                         np.where(step < 0, np.nextafter(stored, np.float32(-np.inf)), stored))
        pts = moved.astype(float)
    return pts, depth


def surface_columns(positions: np.ndarray, x_lo: float, x_hi: float, spacing: float, z_bed: float,
                    width: float | None = None, gap: float | None = None, exclude: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height of the soil resting on the bed, per column, from the volume of its particles.

    In each column the particles are stacked from the bottom; the resting soil is the lowest contiguous
    stack (a vertical gap larger than ``gap``, default 3 spacings, ends it: soil in a lifted bucket or
    in flight is not pile). The column's surface height is ``z_bed`` plus the area of its resting
    particles (``spacing^2`` each) over the column width, so the area under the profile equals the
    resting particles' area exactly (particle-count noise is about one spacing^2 per column).

    Parameters
    ----------
    positions : numpy.ndarray
        Particle positions (N, 2) [m].
    x_lo, x_hi : float
        Range of simulated soil [m].
    spacing : float
        Particle lattice spacing [m] (each particle stands for ``spacing^2`` of soil).
    z_bed : float
        Floor of the soil bed [m].
    width : float
        Column width [m]; default two spacings.
    gap : float
        Largest vertical gap inside a resting stack [m]; default three spacings.
    exclude : numpy.ndarray
        Boolean mask of particles that are never resting (those inside the bucket).

    Returns
    -------
    centres, heights : numpy.ndarray
        Column centres and surface heights [m].
    resting : numpy.ndarray
        Boolean mask of the particles that belong to a column's resting stack.
    """
    gap = 3.0 * spacing if gap is None else gap
    width = 2.0 * spacing if width is None else width
    count = max(1, int(round((x_hi - x_lo) / width)))
    width = (x_hi - x_lo) / count
    centres = x_lo + width * (np.arange(count) + 0.5)
    resting = np.zeros(len(positions), dtype=bool)
    col = np.floor((positions[:, 0] - x_lo) / width).astype(int)
    col = np.clip(col, 0, count - 1)
    order = np.lexsort((positions[:, 1], col))
    if exclude is not None:
        order = order[~np.asarray(exclude, dtype=bool)[order]]
    cols = col[order]
    starts = np.flatnonzero(np.r_[True, cols[1:] != cols[:-1]])
    ends = np.r_[starts[1:], len(order)]
    for a, b in zip(starts, ends, strict=True):
        z = positions[order[a:b], 1]
        jumps = np.flatnonzero(np.diff(z) > gap)
        last = jumps[0] if jumps.size else len(z) - 1
        resting[order[a:a + last + 1]] = True
    area = np.bincount(col[resting], minlength=count) * spacing * spacing
    return centres, z_bed + area / width, resting
