"""Plane-strain MLS-MPM on Taichi: Hencky elasticity, Mohr-Coulomb plasticity, a rigid kinematic tool.

One step (Hu et al. 2018, MLS-MPM with APIC transfers, quadratic B-splines)::

    particle -> grid   mass, momentum and the Kirchhoff stress of the elastic deformation gradient F
    grid               v = p / m + dt g; the tool's contact on the nodes it covers; domain walls
    grid -> particle   v, C (APIC), F <- (I + dt C) F, Mohr-Coulomb return mapping, x <- x + dt v

Soil: Hencky (log-strain) elasticity, ``tau = U (2 mu eps + lambda tr(eps) I) U^T`` for ``F = U exp(eps) V^T``,
and a plane-strain Mohr-Coulomb yield surface on the in-plane principal Kirchhoff stresses (tension
positive) ``q <= c cos(phi) - p sin(phi)`` with ``p`` the mean and ``q`` half the difference. The return
mapping keeps the volume (no dilatancy, as Klar et al. 2016 for sand): a state outside the cone has its
deviatoric log strain scaled onto the cone; a state beyond the apex (tension above ``c / tan(phi)``)
returns to the apex.

Tool: plates in a body frame, pose prescribed each step. A grid node within ``contact_band`` cells of a
plate (measured normal to it, and within the plate's length: the band has square ends, so a blade
reaches exactly its own depth) is in contact with its nearest plate; the normal is the plate's normal
on the node's side. When the node
moves into the plate (relative normal velocity < 0) its normal velocity is set to the tool's and its
tangential slip is limited by Coulomb friction plus adhesion: the tangential impulse the plate can apply
is ``tan(delta) m |v_n| + c_a dx^2 / h dt`` (``c_a`` spread over the nodes of a band ``h`` thick).
Nodes moving away are left free (the soil may leave the tool). The force of the soil on the tool is
the momentum these corrections remove, ``-sum m dv / dt``.

Transfers do not cross plates (compatible particle-in-cell, CPIC, after Hu et al. 2018): a particle and
a grid node on opposite sides of a plate exchange nothing in particle -> grid (the stress and APIC
impulse the node would have received goes to the plate instead: it sums to zero over a particle's
nodes, so dropping it would create momentum), and in grid -> particle such a node is replaced by the
particle's own velocity with any motion into the plate (relative to the tool) removed. A particle guard
is the last safety net: a particle that would cross a plate, or come within ``0.25 dx`` of it, is put
back on its side and its normal velocity relative to the tool is removed; that momentum is part of the
tool force too, and the count and impulse are reported.

Domain: a box with frictionless side walls, a top lid and a sticky (or frictionless) floor. Forces and
masses are per metre of out-of-plane width (plane strain).

Taichi is imported on first use (:mod:`._backend`); all data live in fields allocated with spare
capacity and reused by later solvers of the same process, so the kernels compile once per process.
The kernels are in :mod:`._kernels` (how they avoid atomic additions on the CPU and why); the old ones,
kept for comparison, in :mod:`._legacy` (``legacy=True``). On the CPU the results are deterministic for
given inputs and a given ``threads`` setting, whatever the number of threads Taichi runs (the particles
are split into ``threads`` lanes with their own grid copies, added in lane order); the legacy kernels are
deterministic on one thread only, GPU backends (atomic scatter) not at all.
"""

# No ``from __future__ import annotations`` here: Taichi reads the kernels' annotations at definition.
import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._backend import BACKENDS, initialised_backend, taichi_module
from ._kernels import FLOAT_PARAMS, INT_PARAMS, POSE_CHUNK, build_kernels
from ._legacy import build_legacy_kernels
from .soil import ContinuumSoil
from .tool import MAX_PLATES, ToolShape, Trajectory

#: Gravity [m/s^2].
GRAVITY = 9.81
#: Particles per cell along each axis.
PARTICLES_PER_CELL = 2
#: Nodes kept free between the domain box and the walls (the walls act on nodes 0..WALL_NODES).
WALL_NODES = 2
#: Distance [cells] the particle guard keeps particles away from a plate.
GUARD_CELLS = 0.25
#: How the new kernels update an elastic particle's deformation gradient (``MPMSolver(elastic_f=...)``).
ELASTIC_F = ("exact", "svd")


@dataclass(frozen=True)
class Domain:
    """Simulation box [m]: soil and tool stay inside ``(x_min, z_min)`` .. ``(x_max, z_max)``.

    ``x_min``, ``x_max`` are frictionless walls, ``z_min`` the floor, ``z_max`` a lid.
    """

    x_min: float
    z_min: float
    x_max: float
    z_max: float

    def __post_init__(self) -> None:
        values = (self.x_min, self.z_min, self.x_max, self.z_max)
        if not all(math.isfinite(v) for v in values) or self.x_max <= self.x_min or self.z_max <= self.z_min:
            raise ValueError(f"Domain needs finite x_min < x_max and z_min < z_max, got {values}")


class _Fields:
    """Taichi fields and kernels with fixed capacities (reused across solvers in one process).

    ``mode``: ``"lanes"`` (CPU, :mod:`._kernels` without atomics, ``lanes`` grid copies), ``"atomic"``
    (GPU, :mod:`._kernels` with atomic scatter) or ``"legacy"`` (:mod:`._legacy`, the old kernels).
    ``svd_f``: :mod:`._kernels` rebuilding ``F`` from its SVD each step (``MPMSolver(elastic_f="svd")``).
    """

    def __init__(self, ti: Any, particles: int, nx: int, nz: int, lanes: int, mode: str, svd_f: bool = False) -> None:
        self.ti = ti
        self.particles, self.nx, self.nz, self.lanes, self.mode = particles, nx, nz, lanes, mode
        self.svd_f = svd_f
        self.in_use = False
        fb = ti.FieldsBuilder()
        self.x = ti.Vector.field(2, ti.f32)
        self.v = ti.Vector.field(2, ti.f32)
        self.C = ti.Matrix.field(2, 2, ti.f32)
        self.F = ti.Matrix.field(2, 2, ti.f32)
        self.tau = ti.Matrix.field(2, 2, ti.f32)
        self.near_flag = ti.field(ti.i32)
        fb.dense(ti.i, particles).place(self.x, self.v, self.C, self.F, self.tau, self.near_flag)
        self.grid_v = ti.Vector.field(2, ti.f32)
        self.grid_m = ti.field(ti.f32)
        fb.dense(ti.ij, (nx, nz)).place(self.grid_v, self.grid_m)
        self.lane_v = ti.Vector.field(2, ti.f32)
        self.lane_m = ti.field(ti.f32)
        fb.dense(ti.ijk, (lanes, nx, nz)).place(self.lane_v, self.lane_m)
        self.plate_a = ti.Vector.field(2, ti.f32)
        self.plate_b = ti.Vector.field(2, ti.f32)
        self.world_a = ti.Vector.field(2, ti.f32)
        self.world_b = ti.Vector.field(2, ti.f32)
        fb.dense(ti.i, MAX_PLATES).place(self.plate_a, self.plate_b, self.world_a, self.world_b)
        self.box = ti.Vector.field(4, ti.f32)
        fb.dense(ti.i, 2).place(self.box)
        self.iparam = ti.field(ti.i32)
        self.fparam = ti.field(ti.f32)
        fb.dense(ti.i, len(INT_PARAMS)).place(self.iparam)
        fb.dense(ti.i, len(FLOAT_PARAMS)).place(self.fparam)
        self.pose = ti.field(ti.f32)
        fb.dense(ti.ij, (POSE_CHUNK + 1, 3)).place(self.pose)
        self.lane_impulse = ti.Vector.field(2, ti.f64)
        self.lane_guard_impulse = ti.Vector.field(2, ti.f64)
        self.lane_guarded = ti.field(ti.i64)
        fb.dense(ti.i, lanes).place(self.lane_impulse, self.lane_guard_impulse, self.lane_guarded)
        self.impulse = ti.Vector.field(2, ti.f64)
        self.guard_impulse = ti.Vector.field(2, ti.f64)
        self.guarded = ti.field(ti.i64)
        fb.place(self.impulse, self.guard_impulse, self.guarded)
        self.tree = fb.finalize()
        if mode == "legacy":
            self.substep, self.reset_counters = build_legacy_kernels(self)
            self.init_stress = None
        else:
            self.substep, self.reset_counters, self.init_stress = build_kernels(self, lanes, mode == "atomic", svd_f)

    def destroy(self) -> None:
        self.tree.destroy()


_POOL: list[_Fields] = []


def _acquire_fields(ti: Any, particles: int, nx: int, nz: int, lanes: int, mode: str, svd_f: bool = False) -> _Fields:
    def same_kernels(f: _Fields) -> bool:
        return not f.in_use and f.mode == mode and f.lanes == lanes and f.svd_f == svd_f

    for fields in _POOL:
        if same_kernels(fields) and fields.particles >= particles and fields.nx >= nx and fields.nz >= nz:
            fields.in_use = True
            return fields
    # grow with spare room so that slightly larger scenes reuse the allocation (and the compiled kernels)
    cap_p = int(math.ceil(particles * 1.25 / 4096.0)) * 4096
    cap_x = int(math.ceil(nx * 1.1 / 16.0)) * 16
    cap_z = int(math.ceil(nz * 1.1 / 16.0)) * 16
    for old in [f for f in _POOL if same_kernels(f)]:
        cap_p, cap_x, cap_z = max(cap_p, old.particles), max(cap_x, old.nx), max(cap_z, old.nz)
        old.destroy()
        _POOL.remove(old)
    fields = _Fields(ti, cap_p, cap_x, cap_z, lanes, mode, svd_f)
    fields.in_use = True
    _POOL.append(fields)
    return fields


def _release(fields: _Fields) -> None:
    fields.in_use = False


class MPMSolver:
    """A plane-strain MPM simulation of soil particles and one rigid kinematic tool.

    Parameters
    ----------
    soil : ContinuumSoil
        The material.
    domain : Domain
        The box [m]; particles must lie inside it, at least two cells from its sides.
    dx : float
        Grid cell size [m].
    particles : numpy.ndarray
        Initial particle positions (N, 2) [m] (x, z), each standing for a ``(dx / 2)^2`` area.
    tool : ToolShape or None
        The tool's plates (None: no tool).
    contact_band : float
        Thickness of the tool's contact band [cells]: nodes closer than ``contact_band * dx`` to a plate
        are in contact. Default 1 (the prototype trial: 2 cells lowered the blade force by 15 %).
    cfl : float
        Time step as a fraction of ``dx / c_p`` (P-wave speed). Default 0.3.
    sticky_floor : bool
        Floor nodes hold the soil still (True, a soil bed on rock) or let it slide (False).
    threads : int
        Taichi CPU threads (used at the process's first Taichi initialisation only) and, on the CPU, the
        number of lanes the particles are split into (:mod:`._kernels`): the result depends on this
        setting (the summation order of the grid) and not on how many threads Taichi actually runs.
    legacy : bool
        Run the kernels as they were before the single-thread rewrite (:mod:`._legacy`: an SVD of ``F``
        in particle -> grid, atomic scatter; 2.4 times the cost on one thread). For comparisons only.
    backend : str
        ``"cpu"`` (default), ``"gpu"`` or ``"auto"`` (a GPU where Taichi finds one, else the CPU); used at
        the process's first Taichi initialisation only (:func:`._backend.taichi_module`). On a GPU the
        scatter is atomic and the result is not bit-reproducible.
    scatter : str
        ``"auto"`` (default: ``"lanes"`` on the CPU, ``"atomic"`` on a GPU), ``"lanes"`` or ``"atomic"``
        (the GPU kernels, also runnable on the CPU, e.g. to test them where no GPU is).
    elastic_f : str
        ``"exact"`` (default): a particle that stays elastic keeps its deformation gradient as multiplied,
        ``F <- (I + dt C) F``. ``"svd"``: every ``F`` is rebuilt from its SVD each step, ``U exp(log sigma) V^T``,
        as the legacy kernels did: a rounding that accumulates where the soil should rest (it makes the smooth
        wall's at-rest force creep, and accounts for the old and new kernels' 6.5 % difference there;
        ``docs/results/mpm_reproducibility.md``). For comparisons; not with ``legacy=True``, which always does it.
    """

    def __init__(self, soil: ContinuumSoil, domain: Domain, dx: float, particles: np.ndarray, *,
                 tool: ToolShape | None = None, contact_band: float = 1.0, cfl: float = 0.3,
                 sticky_floor: bool = True, threads: int = 1, legacy: bool = False, backend: str = "cpu",
                 scatter: str = "auto", elastic_f: str = "exact") -> None:
        if not isinstance(soil, ContinuumSoil):
            raise ValueError(f"soil must be a ContinuumSoil, got {type(soil).__name__}")
        if not (isinstance(dx, (int, float)) and math.isfinite(dx) and dx > 0.0):
            raise ValueError(f"dx must be a positive cell size in metres, got {dx!r}")
        if not (math.isfinite(contact_band) and 0.25 <= contact_band <= 4.0):
            raise ValueError(f"contact_band must be in [0.25, 4] cells, got {contact_band!r}")
        if not (math.isfinite(cfl) and 0.0 < cfl <= 0.5):
            raise ValueError(f"cfl must be in (0, 0.5], got {cfl!r}")
        pts = np.asarray(particles, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) == 0 or not np.all(np.isfinite(pts)):
            raise ValueError("particles must be a non-empty finite (N, 2) array of (x, z) positions")
        self.soil, self.domain, self.dx = soil, domain, float(dx)
        self.tool = tool
        self.contact_band = float(contact_band)
        self.cfl = float(cfl)
        self.sticky_floor = bool(sticky_floor)
        self.x0 = domain.x_min - WALL_NODES * self.dx
        self.z0 = domain.z_min - WALL_NODES * self.dx
        self.nx = int(math.ceil((domain.x_max - domain.x_min) / self.dx)) + 2 * WALL_NODES + 1
        self.nz = int(math.ceil((domain.z_max - domain.z_min) / self.dx)) + 2 * WALL_NODES + 1
        lo = np.array([domain.x_min, domain.z_min])
        hi = np.array([self.x0 + (self.nx - 1 - WALL_NODES) * self.dx, self.z0 + (self.nz - 1 - WALL_NODES) * self.dx])
        if np.any(pts < lo - 1e-9) or np.any(pts > hi + 1e-9):
            raise ValueError("particles must lie inside the domain")
        self.n = len(pts)
        self.particle_volume = (self.dx / PARTICLES_PER_CELL) ** 2
        self.particle_mass = soil.density * self.particle_volume
        self.dt_max = self.cfl * self.dx / soil.p_wave_speed
        self.time = 0.0
        self.steps = 0
        self._bounds = (float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))
        if not isinstance(legacy, bool):
            raise ValueError(f"legacy must be True or False, got {legacy!r}")
        if elastic_f not in ELASTIC_F:
            raise ValueError(f"elastic_f must be one of {ELASTIC_F}, got {elastic_f!r}")
        if legacy and elastic_f != "exact":
            raise ValueError("elastic_f applies to the new kernels; legacy=True always rebuilds F from its SVD")
        if backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
        ti = taichi_module(threads, backend)
        self._ti = ti
        if scatter not in ("auto", "lanes", "atomic"):
            raise ValueError(f"scatter must be 'auto', 'lanes' or 'atomic', got {scatter!r}")
        if scatter == "auto":
            scatter = "lanes" if initialised_backend() == "cpu" else "atomic"
        self.kernels = "legacy" if legacy else scatter
        self.lanes = threads if self.kernels == "lanes" else 1
        self.elastic_f = elastic_f
        self._f = _acquire_fields(ti, self.n, self.nx, self.nz, self.lanes, self.kernels, elastic_f == "svd")
        self._finalizer = weakref.finalize(self, _release, self._f)
        self._load(pts)

    # ------------------------------------------------------------- set-up
    def _load(self, pts: np.ndarray) -> None:
        f = self._f
        cap = f.particles
        xs = np.zeros((cap, 2), dtype=np.float32)
        xs[: self.n] = pts
        f.x.from_numpy(xs)
        f.v.from_numpy(np.zeros((cap, 2), dtype=np.float32))
        f.C.from_numpy(np.zeros((cap, 2, 2), dtype=np.float32))
        eye = np.zeros((cap, 2, 2), dtype=np.float32)
        eye[:, 0, 0] = eye[:, 1, 1] = 1.0
        f.F.from_numpy(eye)
        plates_a = np.zeros((MAX_PLATES, 2), dtype=np.float32)
        plates_b = np.ones((MAX_PLATES, 2), dtype=np.float32)
        if self.tool is not None:
            for k, plate in enumerate(self.tool.plates):
                plates_a[k] = plate.start
                plates_b[k] = plate.end
        f.plate_a.from_numpy(plates_a)
        f.plate_b.from_numpy(plates_b)
        f.lane_v.fill(0.0)
        f.lane_m.fill(0.0)
        f.reset_counters()
        self._stress_stale = True

    def set_geostatic_stress(self, overburden: np.ndarray, lateral_ratio: float | None = None) -> None:
        """Start every particle at the elastic strain of a geostatic stress state.

        ``sigma_z = -rho g h`` with ``h`` the particle's ``overburden`` depth [m] below the surface and
        ``sigma_x = K sigma_z`` with ``K = lateral_ratio`` (default: the soil's elastic at-rest ratio).
        """
        h = np.clip(np.asarray(overburden, dtype=float), 0.0, None)
        if h.shape != (self.n,):
            raise ValueError(f"overburden must have one depth per particle ({self.n}), got shape {h.shape}")
        k = self.soil.at_rest_ratio if lateral_ratio is None else float(lateral_ratio)
        mu, lam = self.soil.shear_modulus, self.soil.lame_lambda
        sz = -self.soil.density * GRAVITY * h
        sx = k * sz
        # solve [2mu+lam, lam; lam, 2mu+lam] (ex, ez) = (sx, sz)
        det = (2 * mu + lam) ** 2 - lam**2
        ex = ((2 * mu + lam) * sx - lam * sz) / det
        ez = ((2 * mu + lam) * sz - lam * sx) / det
        Fm = np.zeros((self._f.particles, 2, 2), dtype=np.float32)
        Fm[:, 0, 0] = Fm[:, 1, 1] = 1.0
        Fm[: self.n, 0, 0] = np.exp(ex)
        Fm[: self.n, 1, 1] = np.exp(ez)
        self._f.F.from_numpy(Fm)
        self._stress_stale = True

    # ------------------------------------------------------------- running
    def advance(self, t_end: float, trajectory: Trajectory | None = None, *, damping: float = 0.0) -> np.ndarray:
        """Integrate from the current time to ``t_end`` [s]; return the tool impulse over it [N s per m].

        The impulse is the soil's push on the tool, ``-sum m dv`` over the grid contact corrections and
        the particle guard's; divided by the interval it is the mean force. ``damping`` [1/s] damps grid velocities
        (``v / (1 + damping dt)`` per step; used for settling only).
        """
        span = float(t_end) - self.time
        if span <= 0.0:
            return np.zeros(2)
        f = self._f
        steps = max(1, int(math.ceil(span / self.dt_max - 1e-9)))
        dt = span / steps
        times = self.time + dt * np.arange(steps + 1)
        tool_on = int(self.tool is not None and trajectory is not None)
        if tool_on:
            px = np.interp(times, trajectory.t, trajectory.x)
            pz = np.interp(times, trajectory.t, trajectory.z)
            pa = np.interp(times, trajectory.t, trajectory.angle)
        else:
            px = pz = pa = np.zeros(steps + 1)
        n_plates = len(self.tool.plates) if self.tool is not None else 0
        soil = self.soil
        mu, lam = soil.shear_modulus, soil.lame_lambda
        sin_phi, cos_phi = math.sin(soil.friction_angle), math.cos(soil.friction_angle)
        band = self.contact_band * self.dx
        adhesion_impulse = soil.adhesion * self.dx * self.dx / band * dt
        damp = 1.0 / (1.0 + damping * dt)
        guard = GUARD_CELLS * self.dx
        x_lo, x_hi, z_lo, z_hi = self._bounds
        head = (self.n, self.nx, self.nz, self.x0, self.z0, self.dx, dt, self.particle_volume, self.particle_mass, mu,
                lam, sin_phi, cos_phi, soil.cohesion, GRAVITY, damp, int(self.sticky_floor), tool_on, n_plates)
        tail = (band, math.tan(soil.wall_friction_angle), adhesion_impulse, guard, x_lo, x_hi, z_lo, z_hi)
        before = self.total_impulse
        if self.kernels == "legacy":
            for k in range(steps):
                pose = (float(px[k]), float(pz[k]), float(pa[k]), float(px[k + 1]), float(pz[k + 1]), float(pa[k + 1]))
                f.substep(*head, *pose, *tail)
        else:
            settings = dict(zip(("n", "nx", "nz", "x0", "z0", "dx", "dt", "p_vol", "p_mass", "mu", "lam", "sin_phi",
                                 "cos_phi", "cohesion", "gravity", "damp", "sticky_floor", "tool_on", "n_plates"),
                                head, strict=True))
            settings.update(zip(("band", "tan_delta", "adhesion_impulse", "guard", "x_lo", "x_hi", "z_lo", "z_hi"),
                                tail, strict=True))
            f.iparam.from_numpy(np.array([settings[k] for k in INT_PARAMS], dtype=np.int32))
            f.fparam.from_numpy(np.array([settings[k] for k in FLOAT_PARAMS], dtype=np.float32))
            if self._stress_stale:
                f.init_stress(self.n, mu, lam)
            self._stress_stale = False
            poses = np.zeros((POSE_CHUNK + 1, 3), dtype=np.float32)
            for first in range(0, steps, POSE_CHUNK):
                count = min(POSE_CHUNK, steps - first)
                poses[: count + 1] = np.column_stack([px, pz, pa])[first: first + count + 1]
                f.pose.from_numpy(poses)
                for k in range(count):
                    f.substep(k)
        self.time = float(t_end)
        self.steps += steps
        return self.total_impulse - before

    # ------------------------------------------------------------- reading
    def positions(self) -> np.ndarray:
        """Particle positions (N, 2) [m]."""
        return self._f.x.to_numpy()[: self.n].astype(float)

    def velocities(self) -> np.ndarray:
        """Particle velocities (N, 2) [m/s]."""
        return self._f.v.to_numpy()[: self.n].astype(float)

    def deformation_gradients(self) -> np.ndarray:
        """Elastic deformation gradients (N, 2, 2)."""
        return self._f.F.to_numpy()[: self.n].astype(float)

    def kinetic_energy(self) -> float:
        """Kinetic energy of the particles [J per m]."""
        v = self.velocities()
        return float(0.5 * self.particle_mass * np.sum(v * v))

    @property
    def total_impulse(self) -> np.ndarray:
        """Tool impulse since the solver started [N s per m] (grid contact and particle guard)."""
        return self._counter("impulse") + self.guard_impulse

    @property
    def guard_impulse(self) -> np.ndarray:
        """Part of the tool impulse so far [N s per m] that came through the particle guard."""
        return self._counter("guard_impulse")

    @property
    def guard_corrections(self) -> int:
        """Particle-steps corrected by the plate guard so far."""
        return int(self._counter("guarded"))

    def _counter(self, name: str) -> np.ndarray:
        """A counter summed over the lanes in lane order (the legacy kernels' 0-D field)."""
        if self.kernels == "legacy":
            return getattr(self._f, name).to_numpy().astype(float)
        lanes = getattr(self._f, "lane_" + name).to_numpy()[: self.lanes].astype(float)
        total = lanes[0].copy()
        for row in lanes[1:]:
            total += row
        return total

    # ------------------------------------------------------------- state
    def state(self) -> dict[str, np.ndarray]:
        """Everything the next step depends on, and the counters, as arrays (:meth:`restore` puts it back).

        Restoring a state into a solver built with the same inputs continues bit for bit as the solver
        the state came from (the settled-pile cache, :mod:`.settle_cache`).
        """
        f, n = self._f, self.n
        out = {name: getattr(f, name).to_numpy()[:n] for name in ("x", "v", "C", "F", "tau")}
        for name in ("lane_impulse", "lane_guard_impulse", "lane_guarded"):
            out[name] = getattr(f, name).to_numpy()[: self.lanes]
        for name in ("impulse", "guard_impulse", "guarded"):
            out[name] = getattr(f, name).to_numpy()
        out["clock"] = np.array([self.time, float(self.steps), float(self._stress_stale)])
        return out

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Put back a :meth:`state` of a solver with the same particle count, kernels and lanes."""
        f, n = self._f, self.n
        for name in ("x", "v", "C", "F", "tau"):
            field = getattr(f, name)
            data = np.asarray(state[name])
            if data.shape[0] != n:
                raise ValueError(f"state has {data.shape[0]} particles, the solver {n}")
            full = field.to_numpy()
            full[:n] = data
            field.from_numpy(full)
        for name in ("lane_impulse", "lane_guard_impulse", "lane_guarded"):
            field = getattr(f, name)
            data = np.asarray(state[name])
            if data.shape[0] != self.lanes:
                raise ValueError(f"state has {data.shape[0]} lanes, the solver {self.lanes}")
            full = field.to_numpy()
            full[: self.lanes] = data
            field.from_numpy(full)
        for name in ("impulse", "guard_impulse", "guarded"):
            getattr(f, name).from_numpy(np.asarray(state[name]))
        clock = np.asarray(state["clock"], dtype=float)
        self.time, self.steps, self._stress_stale = float(clock[0]), int(clock[1]), bool(clock[2])

    def close(self) -> None:
        """Give the fields back to the process's pool (the solver is unusable afterwards)."""
        self._finalizer()

    def __enter__(self) -> "MPMSolver":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
