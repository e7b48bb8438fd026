"""The DEM scenario's settings: soil, scale, slab, particles; its paths; the tiny CI scenario.

The scene is a geometrically scaled model of the project's default scenario: the default pile
(:meth:`Pile.trapezoid`, 1 m high), the default bucket (:class:`Bucket`) and the Fig. 8 paths
(:func:`paper_paths`) are all scaled by ``scale`` (default 0.6) about the pile toe; the time axis is not
scaled (4.67 s, 281 samples at 60 Hz). The tip path is raised by one particle radius (the granular bed
replaces the paper's rigid ground; a blade skimming the bed's top layer jams single particles). Forces
and masses are NOT rescaled: a log holds the forces on the simulated slab, and its ``bucket.width`` is
the slab width, so the FEE (linear in the width ``w``, with ``W_load`` from a fill volume of the same
slab) compares like with like.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wheelloader.estimator import Bucket, BucketPath, ParameterError, WheelloaderError, bezier_path, paper_paths

#: Command that installs Yade on Debian/Ubuntu.
YADE_INSTALL = "sudo apt-get update && sudo apt-get install -y yade"
#: Soils the scenario knows (counterparts of the paper's Table 2; see the README beside this module).
SOILS: tuple[str, ...] = ("gravel", "sand", "dirt", "modified_sand")


class YadeNotFoundError(WheelloaderError, RuntimeError):
    """The ``yade`` executable is not on PATH."""


class DemRunError(WheelloaderError, RuntimeError):
    """Yade exited with an error."""


@dataclass(frozen=True)
class DemConfig:
    """Parameters of one DEM scenario run.

    Parameters
    ----------
    soil : str
        One of :data:`SOILS`.
    scale : float
        Geometric scale of pile, bucket and paths relative to the project
        defaults (1 m pile, 0.45 m bucket floor) [-].
    slab_width : float
        Slab (and bucket) width in y [m].
    radius, radius_spread : float
        Mean particle radius [m] and relative half-width of the uniform radius range.
    young : float
        Young's modulus of particles and bucket [Pa] (reduced from steel/rock
        values so that the time step is ~2e-4 s; see the README beside this module).
    seed : int
        Seed of the particle deposition.
    slope_deg : float
        Front slope of the pile [deg].
    top_length : float
        Flat top of the simulated pile up to its back wall [m].
    bed : float
        Soil bed depth under the pile and in front of it [m].
    bulk_density : float or None
        Override of the soil's target bulk density [kg/m^3].
    hold : float
        Hold at the end pose after each path [s] (measures the carried load).
    between : float
        Settling time between the cycles of a multi-cycle run [s].
    damping : float
        Newton (local) damping during the cycles [-].
    threads : int
        Yade OpenMP threads (``-j``); 1 is bit-reproducible.
    lift : float or None
        Path offset in z [m]; None = one particle radius.
    """

    soil: str = "gravel"
    scale: float = 0.6
    slab_width: float = 0.35
    radius: float = 0.03
    radius_spread: float = 0.15
    young: float = 5e7
    seed: int = 1
    slope_deg: float = 30.0
    top_length: float = 0.4
    bed: float = 0.2
    bulk_density: float | None = None
    hold: float = 0.4
    between: float = 0.3
    damping: float = 0.0
    threads: int = 1
    lift: float | None = None

    def __post_init__(self) -> None:
        if self.soil not in SOILS:
            raise ParameterError(f"soil must be one of {list(SOILS)}, got {self.soil!r}")
        for name in ("scale", "slab_width", "radius", "young", "slope_deg", "top_length", "bed", "hold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ParameterError(f"DemConfig.{name} must be > 0, got {value!r}")
        if not 0.0 <= self.radius_spread < 0.5:
            raise ParameterError(f"radius_spread must be in [0, 0.5), got {self.radius_spread!r}")
        if self.slab_width < 4 * self.radius * (1 + self.radius_spread):
            raise ParameterError(f"slab_width {self.slab_width} m must be at least 4 particle radii")
        if self.bulk_density is not None and not self.bulk_density > 0:
            raise ParameterError(f"bulk_density must be > 0 kg/m^3, got {self.bulk_density!r}")
        if not (isinstance(self.threads, int) and self.threads >= 1):
            raise ParameterError(f"threads must be a positive int, got {self.threads!r}")

    @property
    def pile_height(self) -> float:
        """Pile height [m]: the default pile's 1 m times ``scale``."""
        return 1.0 * self.scale

    @property
    def path_lift(self) -> float:
        """z offset of the scaled paths [m]."""
        return self.radius if self.lift is None else self.lift

    def bucket(self) -> Bucket:
        """The simulated bucket as a :class:`Bucket`: default geometry x ``scale``, width = slab width."""
        ref = Bucket()
        area_scale = self.scale**2 * self.slab_width / ref.width
        return Bucket(width=self.slab_width, edge_thickness=ref.edge_thickness * self.scale,
                      floor_length=ref.floor_length * self.scale, capacity=ref.capacity * area_scale,
                      mass=ref.mass * area_scale)

    def yade_args(self) -> list[str]:
        """Scenario options for ``yade_scenario.py``."""
        ref = Bucket()
        args = ["--soil", self.soil, "--radius", repr(self.radius), "--radius-spread", repr(self.radius_spread),
                "--young", repr(self.young), "--seed", str(self.seed), "--slab-width", repr(self.slab_width),
                "--pile-height", repr(self.pile_height), "--slope-deg", repr(self.slope_deg),
                "--top-length", repr(self.top_length), "--bed", repr(self.bed),
                "--floor-length", repr(ref.floor_length * self.scale),
                "--back-height", repr(BACK_HEIGHT * self.scale), "--top-plate", repr(TOP_PLATE * self.scale),
                "--hold", repr(self.hold), "--between", repr(self.between), "--damping", repr(self.damping)]
        if self.bulk_density is not None:
            args += ["--bulk-density", repr(self.bulk_density)]
        return args


#: Back-plate height and top-plate length of the full-scale bucket [m] (floor 0.45 m: struck capacity
#: 0.135 m^2 per metre of width, heaped about the Bucket default 0.2 m^3 per metre).
BACK_HEIGHT = 0.45
TOP_PLATE = 0.15


# --------------------------------------------------------------------------- paths
def _scaled(path: BucketPath, config: DemConfig, name: str | None = None) -> BucketPath:
    return BucketPath(path.t, path.x * config.scale, path.z * config.scale + config.path_lift, path.blade_angle,
                      name or path.name)


def scenario_paths(config: DemConfig | None = None) -> list[BucketPath]:
    """The four Fig. 8-style paths (:func:`paper_paths`), scaled about the toe (x = 0) and lifted."""
    config = config or DemConfig()
    return [_scaled(p, config) for p in paper_paths(0.0)]


def dual_cycle_paths(config: DemConfig | None = None) -> tuple[BucketPath, BucketPath]:
    """Fig. 9-style pair: path 1, then a path from the same start reaching 0.3 m (full scale) further in.

    The second cycle digs the surface the first carved (a run with both paths
    dumps the bucket between them).
    """
    config = config or DemConfig()
    first = paper_paths(0.0)[0]
    second = bezier_path((-0.10, 0.03), (1.50, 0.05), (1.75, 1.20), curl_from=0.6, name="dual cycle 2")
    return _scaled(first, config, "dual cycle 1"), _scaled(second, config)


def write_path_csv(path: BucketPath, fname: Path) -> None:
    """Write t, x, z, blade_angle (the scenario's input format)."""
    with open(fname, "w") as fh:
        fh.write("t,x,z,blade_angle\n")
        for row in zip(path.t, path.x, path.z, path.blade_angle, strict=True):
            fh.write(",".join(repr(float(v)) for v in row) + "\n")


def tiny_config(**changes: Any) -> DemConfig:
    """A ~400-sphere scenario that settles and runs in well under a minute (CI smoke test)."""
    base = {"scale": 0.4, "slab_width": 0.28, "radius": 0.035, "top_length": 0.2, "bed": 0.15, "hold": 0.4}
    base.update(changes)
    return DemConfig(**base)


def tiny_path(config: DemConfig | None = None, duration: float = 2.0) -> BucketPath:
    """A short digging path for :func:`tiny_config`; it starts in the air in front of the pile."""
    config = config or tiny_config()
    s = config.scale
    return bezier_path((-0.15 * s, 0.15 * s), (1.0 * s, 0.10 * s), (1.3 * s, 1.1 * s), duration=duration,
                       curl_from=0.5, name="tiny")
