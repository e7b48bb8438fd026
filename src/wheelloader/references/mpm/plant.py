"""The MPM reference plant: dig a bucket path into a pile of soil and log what a machine would measure."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, CycleLog, Pile, SoilParams, as_soil

from ..metrics import blade_frame
from ._backend import BACKENDS, TAICHI_VERSION, initialised_backend, initialised_threads
from .scene import SceneSettings, bucket_scene, surface_columns
from .settle_cache import SettleCache, settle_digest
from .soil import DEFAULT_YOUNGS_MODULUS, ContinuumSoil
from .solver import ELASTIC_F, MPMSolver
from .tool import Trajectory, bucket_shape

#: Default grid cell size [m]; see :class:`MPMPlant` for how it was chosen (a convergence study).
DEFAULT_RESOLUTION = 0.02


@dataclass(frozen=True)
class MPMSettings:
    """Numerical settings of the plant (SI units).

    Parameters
    ----------
    resolution : float
        Grid cell size dx [m]; 2 x 2 particles per cell.
    youngs_modulus : float
        Young's modulus of the soil [Pa] (a numerical stiffness; see :mod:`.soil`).
    poisson_ratio : float or None
        Poisson ratio; None: Jaky's at-rest ratio (:func:`.soil.jaky_poisson_ratio`).
    contact_band : float
        Tool contact band [cells].
    cfl : float
        Time step / (dx / P-wave speed).
    settle_time : float
        Settling under gravity before the cycle [s] (the bucket rests at the path's first pose).
    settle_damping : float
        Grid-velocity damping during settling [1/s] (none during the cycle).
    threads : int
        Taichi CPU threads (effective at the process's first solver) and lanes of the CPU kernels (the
        result depends on this setting, not on the threads Taichi actually runs; see :mod:`.solver`).
        Default 2: both cores of the 2-core machine the plant is measured on (filtered F_R within 0.76 % of
        the old one-thread kernels, as one thread is; ``docs/results/mpm_speed.md``). The shipped
        reference set was made with ``threads=1``.
    backend : str
        ``"cpu"`` (default), ``"gpu"`` (one of Taichi's GPU backends, an error where none works) or
        ``"auto"`` (a GPU where Taichi finds one, else the CPU); effective at the process's first solver.
    legacy : bool
        Run the solver's old kernels (``MPMSolver(legacy=True)``; for comparisons, 2.4 times the cost).
    elastic_f : str
        ``"exact"`` (default) or ``"svd"``: how the new kernels update an elastic particle's deformation
        gradient (``MPMSolver(elastic_f=...)``; ``"svd"`` as the legacy kernels, for comparisons).
    settle_cache : bool
        Keep the settled soil of a scene on disk and restore it when the same scene is dug again
        (:mod:`.settle_cache`; bit-identical forces; default True).
    relax_pile_after : bool
        Hand on the carved pile of a cohesionless soil relaxed to its friction angle (area-conserving,
        :meth:`~wheelloader.estimator.Pile.relaxed`), default True. The resting soil's columns at the end of
        a cycle are noisy (particle counts per 2-spacing column) and stand steeper than repose within the
        simulated time; the next cycle's settling would slump them, so the pile a planner sees is the one
        its soil will rest as. A cohesive soil's pile is handed on as carved.
    scene : SceneSettings
        Bed depth, truncation wall, margins and particle jitter.
    """

    resolution: float = DEFAULT_RESOLUTION
    youngs_modulus: float = DEFAULT_YOUNGS_MODULUS
    poisson_ratio: float | None = None
    contact_band: float = 1.0
    cfl: float = 0.3
    settle_time: float = 0.3
    settle_damping: float = 20.0
    threads: int = 2
    backend: str = "cpu"
    legacy: bool = False
    elastic_f: str = "exact"
    settle_cache: bool = True
    relax_pile_after: bool = True
    scene: SceneSettings = field(default_factory=SceneSettings)

    def __post_init__(self) -> None:
        if not (isinstance(self.resolution, (int, float)) and math.isfinite(self.resolution)
                and 0.002 <= self.resolution <= 0.2):
            raise ValueError(f"resolution must be a cell size in [0.002, 0.2] m, got {self.resolution!r}")
        if not (math.isfinite(self.settle_time) and self.settle_time >= 0.0):
            raise ValueError(f"settle_time must be >= 0 s, got {self.settle_time!r}")
        if not (math.isfinite(self.settle_damping) and self.settle_damping >= 0.0):
            raise ValueError(f"settle_damping must be >= 0 1/s, got {self.settle_damping!r}")
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads < 1:
            raise ValueError(f"threads must be a positive integer, got {self.threads!r}")
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.elastic_f not in ELASTIC_F:
            raise ValueError(f"elastic_f must be one of {ELASTIC_F}, got {self.elastic_f!r}")
        if self.legacy and self.elastic_f != "exact":
            raise ValueError("elastic_f applies to the new kernels; legacy=True always rebuilds F from its SVD")
        for name in ("legacy", "settle_cache"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be True or False, got {getattr(self, name)!r}")
        if not isinstance(self.relax_pile_after, bool):
            raise ValueError(f"relax_pile_after must be True or False, got {self.relax_pile_after!r}")
        if not isinstance(self.scene, SceneSettings):
            raise ValueError(f"scene must be a SceneSettings, got {type(self.scene).__name__}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping."""
        out = {k: getattr(self, k) for k in ("resolution", "youngs_modulus", "poisson_ratio", "contact_band", "cfl",
                                             "settle_time", "settle_damping", "threads", "backend", "legacy",
                                             "relax_pile_after")}
        out["scene"] = {k: getattr(self.scene, k) for k in ("bed_depth", "wall_margin", "front_margin", "top_margin",
                                                            "jitter")}
        out["scene"].update(self.scene.perturbations())  # only when set: logs dug without one compare equal
        if self.elastic_f != "exact":
            out["elastic_f"] = self.elastic_f
        return out


class MPMPlant:
    """Plane-strain MPM continuum reference plant (:class:`wheelloader.references.Plant`).

    Soil: :class:`ContinuumSoil` from the project's soil (gamma, phi, C, delta, C_a; the Bekker
    parameters are the force model's and unused). Bucket: :func:`.tool.bucket_shape` of ``bucket``.
    The forces are computed per metre of width and multiplied by ``bucket.width``; so is the fill.

    Parameters
    ----------
    resolution : float
        Grid cell size [m]. Default :data:`DEFAULT_RESOLUTION` = 0.02 m, chosen by measurement
        (``benchmarks/mpm_verification.py``, gravel, path 1): the filtered F_R (sigma 0.1 s) of dx 2 cm
        and 1.5 cm differ by 4.5 % RMS, of 3 and 2 cm by 11.8 %; a default cycle at 2 cm (17k particles,
        33k steps) costs about 60 s of CPU (``benchmarks/mpm_speed.py``; the old kernels: 174 s).
    bucket : Bucket
        Bucket geometry (default :class:`Bucket`).
    cache_dir : str or Path, optional
        Directory of the settled-soil cache (default :func:`.settle_cache.default_cache_dir`).
    **settings
        Other :class:`MPMSettings` fields (``youngs_modulus``, ``contact_band``, ``threads``, ...).
    """

    name = "mpm"

    def __init__(self, resolution: float = DEFAULT_RESOLUTION, *, bucket: Bucket | None = None,
                 cache_dir: str | Path | None = None, **settings: Any) -> None:
        unknown = set(settings) - set(MPMSettings.__dataclass_fields__) - {"resolution"}
        if unknown:
            raise ValueError(f"unknown MPMPlant setting(s) {sorted(unknown)}; "
                             f"expected some of {sorted(MPMSettings.__dataclass_fields__)}")
        self.settings = MPMSettings(resolution=resolution, **settings)
        if bucket is not None and not isinstance(bucket, Bucket):
            raise ValueError(f"bucket must be a Bucket, got {type(bucket).__name__}")
        self.bucket = bucket or Bucket()
        self.shape = bucket_shape(self.bucket)
        self.cache = SettleCache(cache_dir) if self.settings.settle_cache else None

    def continuum(self, soil: SoilParams | str | ContinuumSoil) -> ContinuumSoil:
        """The continuum material this plant uses for ``soil``."""
        if isinstance(soil, ContinuumSoil):
            return soil
        return ContinuumSoil.from_soil(soil, youngs_modulus=self.settings.youngs_modulus,
                                       poisson_ratio=self.settings.poisson_ratio)

    @property
    def struck_capacity(self) -> float:
        """Volume the bucket's fill outline holds [m^3] (its area, shoelace formula, times the bucket width):
        what the plant counts as fill at most; soil heaped above the strike line is carried, not counted."""
        outline = self.shape.outline
        x, z = outline[:, 0], outline[:, 1]
        area = 0.5 * abs(float(np.dot(x, np.roll(z, -1)) - np.dot(z, np.roll(x, -1))))
        return area * self.bucket.width

    #: :meth:`dig` also runs a controller that acts on the bucket-loading env's observations
    #: (:mod:`.closed_loop`), given the path that bounds where the bucket may go.
    accepts_controller = True

    def dig(self, path: BucketPath, pile: Pile, soil: SoilParams | str | ContinuumSoil, *, seed: int = 0,
            observer: Callable[[float, np.ndarray], None] | None = None, controller: Any = None) -> CycleLog:
        """Dig ``path`` into ``pile`` of ``soil``; see :class:`wheelloader.references.Plant`.

        The bucket rests at the path's first pose while the soil settles (``settle_time``), then follows
        the path, its pose interpolated linearly between samples at every MPM step. ``F_T``, ``F_N``
        are the mean force over each sample's interval (centred on the sample), in the blade frame of
        ``references/dem/yade_scenario.py``; ``fill_volume`` is the volume (mass / density) of the particles inside
        the bucket outline at each sample; ``pile_after`` is the start pile plus the change of the
        resting soil's surface within the simulated range.

        ``observer``, if given, is called at every sample with the time [s] and the particle positions
        (N, 2) [m] (for figures; it does not change the result).

        ``controller``, if given, drives the bucket instead of the path, closed loop: a callable from the
        bucket-loading env's observation to its action, built from this plant's state at every control step
        (:func:`.closed_loop.dig_closed_loop`; its ``env_config`` attribute, if any, is the env's settings).
        ``path`` then gives the start pose and bounds where the bucket may go (the simulated domain).
        """
        if not isinstance(path, BucketPath):
            raise ValueError(f"path must be a BucketPath, got {type(path).__name__}")
        if not isinstance(pile, Pile):
            raise ValueError(f"pile must be a Pile, got {type(pile).__name__}")
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
            raise ValueError(f"seed must be an integer, got {seed!r}")
        if controller is not None:
            from .closed_loop import dig_closed_loop

            return dig_closed_loop(self, path, pile, soil, int(seed), controller)
        traj = Trajectory.from_path(path)
        run = self.begin(traj, pile, soil, int(seed))
        try:
            force, fill = self._follow(run.solver, traj, path.t, traj.poses(), run.start_positions, observer)
            return self.finish(run, path, force, fill)
        finally:
            run.solver.close()

    def begin(self, domain: Trajectory, pile: Pile, soil: SoilParams | str | ContinuumSoil, seed: int) -> CycleStart:
        """A cycle's solver with the soil of ``pile`` settled around the poses of ``domain`` (the bucket resting at
        its first pose, at its first time); the caller advances it and closes it (``run.solver.close()``)."""
        material = self.continuum(soil)
        cfg = self.settings
        wall0 = time.perf_counter()
        scene = bucket_scene(pile, domain, self.shape, cfg.resolution, seed, cfg.scene)
        solver = MPMSolver(material, scene.domain, cfg.resolution, scene.particles, tool=self.shape,
                           contact_band=cfg.contact_band, cfl=cfg.cfl, sticky_floor=True, threads=cfg.threads,
                           legacy=cfg.legacy, backend=cfg.backend, elastic_f=cfg.elastic_f)
        try:
            cache_status = self._settle(solver, scene, material, domain, float(domain.t[0]))
        except BaseException:
            solver.close()
            raise
        return CycleStart(solver, scene, material, pile, soil if isinstance(soil, str) else None,
                          None if isinstance(soil, ContinuumSoil) else as_soil(soil).to_dict(), seed, wall0,
                          time.perf_counter() - wall0, cache_status, solver.positions())

    def finish(self, run: CycleStart, path: BucketPath, force: np.ndarray, fill: np.ndarray) -> CycleLog:
        """The cycle's log from the samples of ``path`` (world-frame mean forces (n, 2) and fills (n,) per metre
        of width) and the solver's end state (the carved pile)."""
        cfg, solver, scene, material, pile = self.settings, run.solver, run.scene, run.material, run.pile
        end_positions = solver.positions()
        tangential, normal = blade_frame(force[:, 0], force[:, 1], path.blade_angle)
        last = (float(path.x[-1]), float(path.z[-1]), float(path.blade_angle[-1]))
        pile_after, balance = _carved_pile(pile, scene, run.start_positions, end_positions,
                                           self.shape.inside(last, end_positions), solver.particle_volume)
        if cfg.relax_pile_after and material.cohesion == 0.0 and material.friction_angle > 0.0:
            pile_after = pile_after.relaxed(material.friction_angle)
        guard_share = float(np.linalg.norm(solver.guard_impulse) / max(1e-12, np.linalg.norm(solver.total_impulse)))
        wall = time.perf_counter() - run.wall0
        width = self.bucket.width
        metadata = {
            "source": "mpm",
            "plant": self.name,
            "soil": run.soil_label,
            "soil_params": run.soil_params,
            "continuum": material.to_dict(),
            "settings": cfg.to_dict(),
            "resolution": cfg.resolution,
            "youngs_modulus": material.youngs_modulus,
            "contact_band": cfg.contact_band,
            "seed": run.seed,
            "particles": int(len(scene.particles)),
            "domain": [scene.domain.x_min, scene.domain.z_min, scene.domain.x_max, scene.domain.z_max],
            "steps": int(solver.steps),
            "dt_max": solver.dt_max,
            "guard_corrections": int(solver.guard_corrections),
            "guard_impulse_share": guard_share,
            "mass_balance": balance,
            "wall_s": wall,
            "settle_wall_s": run.settle_s,
            "settle_cache": run.cache_status,
            "kernels": solver.kernels,
            "taichi": TAICHI_VERSION,
            "taichi_threads": initialised_threads(),
            "taichi_backend": initialised_backend(),
            "path_name": path.name,
            "width_scaling": "forces and volumes per metre of width x bucket.width",
        }
        return CycleLog(path, tangential * width, normal * width, pile, self.bucket, fill * width, None, pile_after,
                        metadata)

    def _follow(self, solver: MPMSolver, traj: Trajectory, t: np.ndarray, poses: np.ndarray,
                start_positions: np.ndarray, observer: Callable[[float, np.ndarray], None] | None
                ) -> tuple[np.ndarray, np.ndarray]:
        """Advance ``solver`` along the path's samples ``t``: the mean force over each sample's interval
        (centred on the sample) per metre of width [N/m] and the fill at each sample [m^3/m]."""
        mids = 0.5 * (t[1:] + t[:-1])
        n = len(t)
        impulse = np.zeros((n, 2))
        window = np.zeros(n)
        fill = np.zeros(n)
        fill[0] = np.count_nonzero(self.shape.inside(tuple(poses[0]), start_positions)) * solver.particle_volume
        if observer is not None:
            observer(float(t[0]), start_positions)
        for k in range(n):
            if k > 0:
                impulse[k] += solver.advance(t[k], traj)
                window[k] += t[k] - mids[k - 1]
                positions = solver.positions()
                fill[k] = np.count_nonzero(self.shape.inside(tuple(poses[k]), positions)) * solver.particle_volume
                if observer is not None:
                    observer(float(t[k]), positions)
            if k < n - 1:
                impulse[k] += solver.advance(mids[k], traj)
                window[k] += mids[k] - t[k]
        return impulse / window[:, None], fill

    def _settle(self, solver: MPMSolver, scene: Any, material: ContinuumSoil, traj: Trajectory, t0: float) -> str:
        """Settle the soil under gravity until ``t0`` (or restore the cached result); ``"hit"``, ``"miss"`` or
        ``"off"``."""
        cfg = self.settings
        digest = None
        if self.cache is not None and solver.kernels != "atomic":
            first = traj.poses()[0]
            values = {"domain": [scene.domain.x_min, scene.domain.z_min, scene.domain.x_max, scene.domain.z_max],
                      "dx": cfg.resolution, "soil": material.to_dict(), "plates": [
                          [list(p.start), list(p.end)] for p in self.shape.plates],
                      "contact_band": cfg.contact_band, "cfl": cfg.cfl, "settle_time": cfg.settle_time,
                      "settle_damping": cfg.settle_damping, "t0": t0, "t_first": float(traj.t[0]),
                      "pose": [float(v) for v in first], "kernels": solver.kernels, "lanes": solver.lanes,
                      "elastic_f": solver.elastic_f,
                      "backend": initialised_backend(), "taichi": TAICHI_VERSION}
            digest = settle_digest({"particles": scene.particles, "overburden": scene.overburden}, values)
            state = self.cache.load(digest)
            if state is not None:
                solver.restore(state)
                return "hit"
        solver.set_geostatic_stress(scene.overburden)
        solver.time = t0 - cfg.settle_time
        solver.advance(t0, traj, damping=cfg.settle_damping)
        if digest is None:
            return "off"
        self.cache.save(digest, solver.state())
        return "miss"


@dataclass(frozen=True, eq=False)
class CycleStart:
    """A cycle's settled solver (:meth:`MPMPlant.begin`) and what :meth:`MPMPlant.finish` needs besides the samples."""

    solver: MPMSolver
    scene: Any
    material: ContinuumSoil
    pile: Pile
    soil_label: str | None
    soil_params: dict[str, Any] | None
    seed: int
    wall0: float
    settle_s: float
    cache_status: str
    start_positions: np.ndarray


def _carved_pile(pile: Pile, scene: Any, start: np.ndarray, end: np.ndarray, in_bucket: np.ndarray,
                 particle_volume: float) -> tuple[Pile, dict[str, float]]:
    """The start pile plus the change of the resting soil's column heights; the area balance per metre [m^2].

    ``net_area_removed`` (carved minus deposited area of the resting soil) equals ``detached_area_end``
    (the particles no longer resting on the pile: in or on the bucket, in flight) by construction;
    ``fill_area_end`` is the part inside the bucket outline.
    """
    x_lo, x_hi = scene.soil_x
    z_bed = scene.domain.z_min
    centres, before, _ = surface_columns(start, x_lo, x_hi, scene.spacing, z_bed)
    _, after, resting = surface_columns(end, x_lo, x_hi, scene.spacing, z_bed, exclude=in_bucket)
    change = after - before
    xs = pile.x
    inside = (xs >= x_lo) & (xs <= x_hi)
    heights = pile.heights.copy()
    heights[inside] += np.interp(xs[inside], centres, change)
    after_pile = pile.with_heights(heights)
    width = (x_hi - x_lo) / len(centres)
    carved = float(np.sum(np.clip(-change, 0.0, None)) * width)
    deposited = float(np.sum(np.clip(change, 0.0, None)) * width)
    balance = {
        "carved_area": carved,
        "deposited_area": deposited,
        "net_area_removed": carved - deposited,
        "fill_area_end": float(np.count_nonzero(in_bucket) * particle_volume),
        "detached_area_end": float(np.count_nonzero(~resting) * particle_volume),
    }
    return after_pile, balance
