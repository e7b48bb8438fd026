"""The Yade DEM as a plant of the adaptation loop: dig a full-scale path into any (carved) pile.

:class:`DEMPlant` implements :class:`wheelloader.references.Plant` on top of the DEM scenario
(``yade_scenario.py``, one Yade run per cycle). Each cycle deposits a packing of the soil's spheres, carves
it to the pile it is given (``--surface``: the fresh trapezoid or the surface an earlier cycle left), lets it
settle, and digs the path with the scenario's rigid bucket. The carved pile is read back from the particles
(the upper envelope of the resting ones, smoothed by a running mean two particle diameters wide and, for a
cohesionless soil, relaxed to its friction angle, as the MPM plant hands its piles on).

Scale. The scenario is a geometrically scaled slab (:class:`DemConfig`, ``scale`` 0.6 and a 0.35 m slab by
default, the reference set's; time is not scaled). Paths and piles are scaled into it about x = 0 (the toe of
the loop's pile), and its forces and volumes are brought back to the loop's full-scale bucket by geometric
similarity: per metre of width a force of the soil's weight grows with the square of the length scale, so
``F = F_slab / slab_width * bucket.width / scale^2`` and the same for the fill volume. That holds for a
cohesionless soil only (cohesion would scale with the length): a cohesive soil is refused unless
``scale`` is 1. The particles are not scaled: at scale 0.6 the plant is a full-scale pile of spheres of
radius ``radius / scale`` (5 cm at the defaults), coarse beside the MPM plant (the README beside this module: the same
path on another packing differs from itself by 33-109 %).

A cycle costs one settling and one dig (the deposit grows with how far the path reaches); each settled
deposit is cached under its surface's digest.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, CycleLog, ParameterError, Pile, SoilParams, preset

from ..filtering import moving_average
from .config import SOILS, DemConfig
from .runner import DEFAULT_CACHE, run_scenario

#: Room behind the path's farthest tip position to the scenario's back wall, full scale [m] (one bucket
#: floor length plus this).
BACK_MARGIN = 0.6
#: Bed in front of the path's first tip position, full scale [m].
FRONT_MARGIN = 0.15
#: After the dig the load is carried away, the bucket removed and the pile settles this long before its
#: surface is read (scenario time [s]).
SETTLE_AFTER = 0.3


class DEMPlant:
    """The Yade DEM scenario as a reference plant (module docstring).

    Parameters
    ----------
    config : DemConfig, optional
        Scenario settings (default :class:`DemConfig`: scale 0.6, 0.35 m slab, 3 cm spheres). Its ``soil``
        and ``seed`` are replaced per :meth:`dig` (the seed is ``config.seed + seed``).
    cache_dir : str or Path, optional
        Settled-deposit cache (default ``~/.cache/wheelloader/dem`` or ``$WHEELLOADER_DEM_CACHE``).
    work_dir : str or Path, optional
        Where each run's raw output is kept (a subfolder per cycle); default a temporary folder, removed.
    timeout : float, optional
        Wall-clock limit of one Yade run [s].
    progress : callable, optional
        Receives the scenario's progress lines.
    """

    name = "dem"

    def __init__(self, config: DemConfig | None = None, *, cache_dir: str | Path | None = None,
                 work_dir: str | Path | None = None, timeout: float | None = None, progress: Any = None) -> None:
        self.config = config or DemConfig()
        if not isinstance(self.config, DemConfig):
            raise ParameterError(f"config must be a DemConfig, got {type(self.config).__name__}")
        self.cache_dir = Path(cache_dir) if cache_dir is not None else DEFAULT_CACHE
        self.work_dir = None if work_dir is None else Path(work_dir)
        self.timeout = timeout
        self.progress = progress
        self.bucket = Bucket()
        self._runs = 0

    def dig(self, path: BucketPath, pile: Pile, soil: SoilParams | str, *, seed: int = 0) -> CycleLog:
        """Dig ``path`` into ``pile`` of ``soil`` (a name of :data:`SOILS`); see
        :class:`wheelloader.references.Plant`. The log is at full scale: the requested path's times, the
        bucket's measured tip pose scaled back, forces and fill per :attr:`bucket` width."""
        if not isinstance(path, BucketPath):
            raise ParameterError(f"path must be a BucketPath, got {type(path).__name__}")
        if not isinstance(pile, Pile):
            raise ParameterError(f"pile must be a Pile, got {type(pile).__name__}")
        if not isinstance(soil, str) or soil not in SOILS:
            raise ParameterError(f"the DEM plant digs its own soils {sorted(SOILS)}, got {soil!r} (it has no "
                                 "counterpart of arbitrary FEE parameters)")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ParameterError(f"seed must be a non-negative integer, got {seed!r}")
        config = dataclasses.replace(self.config, soil=soil, seed=self.config.seed + int(seed))
        s = config.scale
        if preset(soil).cohesion > 0.0 and s != 1.0:  # the scenario's soils are the Table 2 soils' counterparts
            raise ParameterError(f"soil {soil!r} is cohesive: the DEM plant's similarity scaling (scale {s}) holds "
                                 "for cohesionless soils only; use DemConfig(scale=1.0)")
        x_front = float(min(path.x.min() - FRONT_MARGIN, -FRONT_MARGIN))
        x_back = float(path.x.max() + self.bucket.floor_length + BACK_MARGIN)
        grid = np.arange(x_front, x_back + 1e-9, 0.01)
        heights = np.asarray(pile.surface_height(grid), dtype=float)
        if np.any(heights < -config.bed / s):
            raise ParameterError(f"the pile lies below the DEM bed ({config.bed / s:.2f} m below the toe)")
        scaled = BucketPath(path.t, path.x * s, path.z * s + config.path_lift, path.blade_angle, path.name)
        wall0 = time.perf_counter()
        self._runs += 1
        with tempfile.TemporaryDirectory(prefix="wheelloader-dem-") as tmp:
            work = Path(tmp) if self.work_dir is None else self.work_dir / f"dig{self._runs}"
            work.mkdir(parents=True, exist_ok=True)
            surface = work / "surface.csv"
            np.savetxt(surface, np.column_stack([grid * s, heights * s]), delimiter=",", header="x,z", comments="")
            run = run_scenario(config, [scaled], work, cache_dir=self.cache_dir, progress=self.progress,
                               timeout=self.timeout, extra_args=["--surface", str(surface), "--x-back",
                                                                 repr(x_back * s), "--front", repr(-x_front * s),
                                                                 "--settle-after", repr(SETTLE_AFTER)])
        raw = run.logs[0]
        factor = self.bucket.width / (raw.bucket.width * s * s)
        measured = raw.path
        dug = BucketPath(measured.t, measured.x / s, (measured.z - config.path_lift) / s, measured.blade_angle,
                         path.name)
        after = _carved(pile, raw.pile_after, s, x_front, x_back, config.radius, raw.metadata.get("material"))
        metadata = dict(raw.metadata)
        metadata.update({
            "plant": self.name,
            "soil": soil,
            "seed": int(seed),
            "scale": s,
            "path_name": path.name,
            "wall_s": time.perf_counter() - wall0,
            "scenario_range_m": [x_front, x_back],
            "width_scaling": f"slab forces and volumes x bucket.width / (slab width x scale^2) = x {factor:.4g} "
                             "(geometric similarity, cohesionless soil)",
        })
        return CycleLog(dug, raw.tangential * factor, raw.normal * factor, pile, self.bucket,
                        fill_volume=None if raw.fill_volume is None else raw.fill_volume * factor,
                        pile_after=after, metadata=metadata)


def _carved(pile: Pile, scene_after: Pile | None, s: float, x_front: float, x_back: float, radius: float,
            material: dict[str, float] | None) -> Pile:
    """The loop's pile after a cycle: ``pile`` with the scenario's resting surface (scaled back, smoothed by a
    running mean two particle diameters wide, relaxed to the friction angle for a cohesionless soil) between the
    scenario's front and one bucket length before its back wall."""
    if scene_after is None:
        raise ParameterError("the DEM scenario did not report the carved surface")
    x = np.asarray(pile.x, dtype=float)
    heights = np.array(pile.heights, dtype=float)
    inside = (x >= x_front) & (x <= x_back - BACK_MARGIN)
    sx, sz = np.asarray(scene_after.x, float) / s, np.asarray(scene_after.heights, float) / s
    diameter = 2.0 * radius / s
    smooth = moving_average(sz, rate=1.0 / float(np.median(np.diff(sx))), window_s=2.0 * diameter)
    heights[inside] = np.interp(x[inside], sx, smooth)
    after = pile.with_heights(heights)
    if material is not None and material.get("cohesion", 0.0) == 0.0 and material.get("friction", 0.0) > 0.0:
        after = after.relaxed(float(material["friction"]))
    return after
