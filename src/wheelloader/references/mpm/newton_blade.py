"""The vertical-blade verification case in Newton's implicit MPM (optional extra ``mpm-newton``).

A cross-check of :func:`~wheelloader.references.mpm.verification.run_blade` with an independent,
existing engine: `Newton <https://github.com/newton-physics/newton>`_'s ``SolverImplicitMPM`` (Warp,
CPU device; Daviet & Bertails-Descoubes 2016: implicit, Drucker-Prager with no dilatancy). Newton's
MPM is three-dimensional, so plane strain is approximated by a thin slab of soil between two
frictionless walls (``cells_across`` voxels wide); the blade spans the slab. Forces are reported per
metre of width, in the form of :func:`run_blade`: a :class:`CaseResult` with ``extra['travel']`` and
``extra['heap_mass']`` / ``extra['heap_bin_edges']`` (the soil heaped above the original surface ahead
of the blade, kg per metre of width).

What maps onto what:

* Mohr-Coulomb (phi) -> Newton's Drucker-Prager ``sqrt(J2) <= mu p`` with ``mu = sin(phi)``: the
  plane-strain match for a flow rule without dilatancy (the out-of-plane deviatoric stress vanishes
  in plastic flow, so ``sqrt(J2) = (s1 - s3) / 2`` and ``p = (s1 + s3) / 2``);
* the blade's wall friction delta -> the blade collider's Coulomb coefficient ``tan(delta)`` (Newton
  supports per-shape collider friction and adhesion; the side walls and the far end wall get 0, the
  floor a large coefficient: sticky like the Taichi solver's floor);
* Young's modulus and Poisson ratio as given by the :class:`ContinuumSoil`;
* cohesion and adhesion are not mapped (the cross-check covers cohesionless soils; a soil with
  either raises ``ValueError``).

The blade force is the sum of the collider impulses Newton reports on the blade's nodes
(``SolverImplicitMPM.collect_collider_impulses``) over each sample interval, divided by the interval
and the slab width. Importing this module does not import Newton or Warp; running a case without them
raises :class:`NewtonUnavailableError` naming the install command.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from types import ModuleType
from typing import Any

import numpy as np

from wheelloader.estimator import WheelloaderError

from .soil import ContinuumSoil
from .solver import GRAVITY
from .verification import CaseResult, blade_motion

#: The install command named by the error when Newton is missing.
NEWTON_INSTALL_HINT = 'pip install "wheelloader[mpm-newton]"'
#: The versions the cross-check was written and measured against.
NEWTON_VERSION = "1.8.0"
WARP_VERSION = "1.19.0"


class NewtonUnavailableError(WheelloaderError, ImportError):
    """Newton / Warp (the optional ``mpm-newton`` extra) is not installed."""


def newton_available() -> bool:
    """Whether ``import newton`` and ``import warp`` would succeed (without importing them)."""
    from importlib.util import find_spec

    return find_spec("newton") is not None and find_spec("warp") is not None


def _newton() -> tuple[ModuleType, ModuleType, type]:
    try:
        import newton
        import warp as wp
        from newton.solvers import SolverImplicitMPM
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise NewtonUnavailableError(
            f"the Newton blade cross-check needs Newton {NEWTON_VERSION} and Warp {WARP_VERSION}; install them "
            f"with:  {NEWTON_INSTALL_HINT}") from exc
    return wp, newton, SolverImplicitMPM


@dataclass(frozen=True)
class NewtonBladeSettings:
    """Numerical settings of the Newton slab.

    Parameters
    ----------
    cells_across : int
        Slab width in voxels (the frictionless side walls lie on voxel faces).
    particles_per_cell : int
        Particles per voxel edge (the Taichi solver's 2).
    dt : float
        Time step [s]; an integer number of steps per force sample (see ``samples_per_s``).
    max_iterations, tolerance
        Newton's rheology solver budget and tolerance (its defaults).
    settle : float
        Seconds the bed settles under gravity with the blade at rest before the push (Newton
        starts stress-free; the Taichi case starts geostatic and settles 0.2 s).
    floor_friction : float
        Coulomb coefficient of the floor under the bed (large: sticky).
    youngs_modulus : float or None
        Young's modulus [Pa] of the Newton soil; None: the :class:`ContinuumSoil`'s.
    device : str
        Warp device (``"cpu"``).
    """

    cells_across: int = 2
    particles_per_cell: int = 2
    dt: float = 1.0 / 240.0
    max_iterations: int = 250
    tolerance: float = 1.0e-4
    settle: float = 0.15
    floor_friction: float = 10.0
    youngs_modulus: float | None = None
    device: str = "cpu"

    def __post_init__(self) -> None:
        if isinstance(self.cells_across, bool) or not isinstance(self.cells_across, int) or self.cells_across < 1:
            raise ValueError(f"cells_across must be a positive integer, got {self.cells_across!r}")
        if isinstance(self.particles_per_cell, bool) or not isinstance(self.particles_per_cell, int) \
                or self.particles_per_cell < 1:
            raise ValueError(f"particles_per_cell must be a positive integer, got {self.particles_per_cell!r}")
        for name in ("dt", "tolerance"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not self.settle >= 0.0:
            raise ValueError(f"settle must be >= 0 s, got {self.settle!r}")
        if not self.floor_friction >= 0.0:
            raise ValueError(f"floor_friction must be >= 0, got {self.floor_friction!r}")
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) \
                or self.max_iterations < 1:
            raise ValueError(f"max_iterations must be a positive integer, got {self.max_iterations!r}")


def drucker_prager_friction(friction_angle: float) -> float:
    """Newton's Drucker-Prager coefficient ``mu`` (``sqrt(J2) <= mu p``) matching Mohr-Coulomb phi in
    plane strain without dilatancy: ``sin(phi)``."""
    return math.sin(friction_angle)


def _steps_per_sample(depth: float, soil: ContinuumSoil, dx: float, samples_per_s: float,
                      settings: NewtonBladeSettings) -> int:
    """Check :func:`run_newton_blade`'s arguments; the time steps per output sample."""
    if not depth > 0.0:
        raise ValueError(f"depth must be > 0 m, got {depth!r}")
    if not 0.0 < dx <= depth:
        raise ValueError(f"dx must be in (0, depth], got {dx!r}")
    if soil.cohesion != 0.0 or soil.adhesion != 0.0:
        raise ValueError("the Newton blade cross-check covers cohesionless soils only (cohesion = adhesion = 0); "
                         f"got cohesion {soil.cohesion!r} Pa, adhesion {soil.adhesion!r} Pa")
    steps_per_sample = int(round(1.0 / (samples_per_s * settings.dt)))
    if steps_per_sample < 1 or not math.isclose(steps_per_sample * settings.dt * samples_per_s, 1.0, rel_tol=1e-9):
        raise ValueError(f"1 / samples_per_s ({1.0 / samples_per_s!r} s) must be a whole number of time steps "
                         f"dt = {settings.dt!r} s")
    return steps_per_sample


def _bed_particles(extents: tuple[float, float, float], spacing: float, seed: int) -> np.ndarray:
    """Particle positions (N, 3) [m] filling the box ``extents`` on a grid of ``spacing``, jittered by a
    quarter spacing (seeded)."""
    rng = np.random.default_rng(seed)
    axes = [np.arange(0.5 * spacing, extent - 0.25 * spacing, spacing) for extent in extents]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    pts += rng.uniform(-0.25, 0.25, size=pts.shape) * spacing
    return pts


def _add_walls(wp: Any, builder: Any, smooth: Any, x_end: float, width: float, tall: float, dx: float) -> None:
    """The frictionless side walls (the slab faces y = 0 and y = width) and end walls (x = -0.1, x_end)."""
    for y in (-0.5 * dx, width + 0.5 * dx):
        builder.add_shape_box(-1, xform=wp.transform(wp.vec3(0.5 * x_end - 0.05, y, 0.5 * tall),
                                                     wp.quat_identity()),
                              hx=0.5 * x_end + 0.05 + 2.0 * dx, hy=0.5 * dx, hz=0.5 * tall, cfg=smooth)
    for x in (-0.1 - 0.5 * dx, x_end + 0.5 * dx):  # the Taichi case's domain ends
        builder.add_shape_box(-1, xform=wp.transform(wp.vec3(x, 0.5 * width, 0.5 * tall), wp.quat_identity()),
                              hx=0.5 * dx, hy=0.5 * width + dx, hz=0.5 * tall, cfg=smooth)


def _set_material(mpm: Any, soil: ContinuumSoil, settings: NewtonBladeSettings) -> None:
    """Newton's MPM material for ``soil``: Drucker-Prager friction, no cohesion, no dilatancy."""
    mpm.young_modulus.fill_(soil.youngs_modulus if settings.youngs_modulus is None else settings.youngs_modulus)
    mpm.poisson_ratio.fill_(soil.poisson_ratio)
    mpm.friction.fill_(drucker_prager_friction(soil.friction_angle))
    mpm.yield_pressure.fill_(1.0e12)
    mpm.tensile_yield_ratio.fill_(0.0)
    mpm.yield_stress.fill_(0.0)
    mpm.dilatancy.fill_(0.0)


class _BladeStep:
    """One Newton step with the kinematic blade at its prescribed pose: its centre ``pose[0]`` behind
    ``position(t)`` in x, at ``pose[1:]`` in y and z. A call returns the impulses of the step on the blade and
    on the static colliders (floor, walls). The solver is reset with the blade at its start pose."""

    def __init__(self, solver: Any, state: Any, blade: int, position: Any, pose: tuple[float, float, float],
                 dt: float) -> None:
        self.solver, self.state, self.blade, self.position, self.dt = solver, state, blade, position, dt
        self.blade_half, self.y, self.z = pose
        self.place_blade(0.0, dt)
        solver.reset(state)
        self.body_of_collider = solver.collider_body_index.numpy()

    def place_blade(self, t: float, dt: float) -> None:
        """Put the blade at its pose and velocity of time ``t``."""
        state, blade, position = self.state, self.blade, self.position
        x = float(position(t)) - self.blade_half
        v = (float(position(t + dt)) - float(position(t))) / dt
        q = state.body_q.numpy()
        q[blade] = (x, self.y, self.z, 0.0, 0.0, 0.0, 1.0)
        state.body_q.assign(q)
        qd = state.body_qd.numpy()
        qd[blade] = (v, 0.0, 0.0, 0.0, 0.0, 0.0)
        state.body_qd.assign(qd)

    def collider_impulses(self) -> tuple[np.ndarray, np.ndarray]:
        """The impulses of the last step on the blade and on the static colliders (floor, walls)."""
        impulses, _, colliders = self.solver.collect_collider_impulses(self.state)
        ids = colliders.numpy()
        body = np.where(ids >= 0, self.body_of_collider[np.maximum(ids, 0)], -2)
        values = impulses.numpy().astype(float)
        return values[body == self.blade].sum(axis=0), values[body == -1].sum(axis=0)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        self.place_blade(t, self.dt)
        self.solver.step(self.state, self.state, None, None, self.dt)
        self.solver.project_outside(self.state, self.state, self.dt)
        return self.collider_impulses()


def _settle(step: _BladeStep, settings: NewtonBladeSettings, weight: float) -> tuple[int, float]:
    """Let the bed settle (``settings.settle`` [s], the blade at rest): the steps taken and the static
    colliders' mean vertical reaction over the last quarter of them divided by the bed's ``weight`` [N]."""
    settle_steps = int(round(settings.settle / settings.dt))
    t = -settle_steps * settings.dt
    floor = []
    for _ in range(settle_steps):
        floor.append(step(min(t, 0.0))[1][2])
        t += settings.dt
    # the impulse accounting checked on the bed's weight: the static colliders carry it at rest
    tail = floor[-max(1, settle_steps // 4):]
    return settle_steps, float(-np.mean(tail) / settings.dt / weight) if floor else float("nan")


def run_newton_blade(depth: float, soil: ContinuumSoil, dx: float, *, speed: float = 0.2,
                     travel: float | None = None, seed: int = 0, samples_per_s: float = 60.0,
                     settings: NewtonBladeSettings | None = None) -> CaseResult:
    """The vertical blade of :func:`~wheelloader.references.mpm.verification.run_blade` in Newton.

    The same bed (``depth + max(0.1, depth)`` deep on a rough floor, ``travel + 4 depth + 0.1`` m
    long, a frictionless end wall), the same blade motion (smoothstep ramp to ``speed`` over 0.1 s),
    voxel size ``dx``. Returns the force on the blade per metre of width (x: soil pushing it back is
    negative; z: soil lifting it is positive) averaged over each of the ``samples_per_s`` intervals,
    ``extra['travel']`` per sample [m] and the heaped soil per sample.
    """
    settings = NewtonBladeSettings() if settings is None else settings
    steps_per_sample = _steps_per_sample(depth, soil, dx, samples_per_s, settings)
    wp, newton, solver_cls = _newton()

    travel, duration, position = blade_motion(depth, speed, travel)
    below = max(0.1, depth)
    surface = depth + below
    x_end = travel + 4.0 * depth + 0.1
    width = settings.cells_across * dx
    spacing = dx / settings.particles_per_cell
    pts = _bed_particles((x_end, width, surface), spacing, seed)
    particle_mass = soil.density * spacing**3
    blade_height = depth + 0.3
    blade_half = 0.5 * dx

    wall0 = time.perf_counter()
    with wp.ScopedDevice(settings.device):
        builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=(0.0, 0.0, -GRAVITY))
        solver_cls.register_custom_attributes(builder)
        builder.add_particles(pos=[tuple(p) for p in pts.astype(np.float32)], vel=[(0.0, 0.0, 0.0)] * len(pts),
                              mass=[particle_mass] * len(pts), radius=[0.5 * spacing] * len(pts))
        smooth = newton.ModelBuilder.ShapeConfig(mu=0.0, density=0.0)
        builder.add_ground_plane(cfg=newton.ModelBuilder.ShapeConfig(mu=settings.floor_friction, density=0.0))
        _add_walls(wp, builder, smooth, x_end, width, surface + blade_height, dx)
        blade = builder.add_body(is_kinematic=True, label="blade")
        builder.add_shape_box(blade, hx=blade_half, hy=0.5 * width + dx, hz=0.5 * blade_height,
                              cfg=newton.ModelBuilder.ShapeConfig(mu=math.tan(soil.wall_friction_angle), density=0.0))
        model = builder.finalize()
        _set_material(model.mpm, soil, settings)

        config = solver_cls.Config()
        config.voxel_size = dx
        config.max_iterations = settings.max_iterations
        config.tolerance = settings.tolerance
        solver = solver_cls(model, config)
        state = model.state()
        blade_z = below + 0.5 * blade_height  # the blade's lower edge at the cut depth
        step = _BladeStep(solver, state, blade, position, (blade_half, 0.5 * width, blade_z), settings.dt)
        settle_steps, floor_over_weight = _settle(step, settings, len(pts) * particle_mass * GRAVITY)
        samples = int(round(duration * samples_per_s))
        force = np.zeros((samples, 2))
        heap_bins = np.arange(0.0, x_end + dx, dx)
        heap = []
        t = 0.0
        for k in range(samples):
            impulse = np.zeros(3)
            for _ in range(steps_per_sample):
                impulse += step(t)[0]
                t += settings.dt
            force[k] = impulse[[0, 2]] * samples_per_s / width
            p = state.particle_q.numpy()
            above = p[:, 2] > surface
            counts, _ = np.histogram(p[above, 0] - float(position(t)), bins=heap_bins)
            heap.append(counts * particle_mass / width)
        steps = settle_steps + samples * steps_per_sample
        final = state.particle_q.numpy().astype(float)
        finite = bool(np.all(np.isfinite(final)))
        # soil that got behind the blade above its lower edge (through or around the collider)
        x_face = float(position(t))
        leaked = int(np.sum((final[:, 0] < x_face - dx) & (final[:, 2] > below + dx)))
    wall = time.perf_counter() - wall0
    times = (np.arange(samples) + 0.5) / samples_per_s
    result = CaseResult(times, force, len(pts), steps, wall)
    result.extra["travel"] = position(times)
    result.extra["heap_mass"] = np.array(heap)
    result.extra["heap_bin_edges"] = heap_bins
    result.extra.update(width=width, dt=settings.dt, settings=asdict(settings), finite=finite,
                        floor_reaction_over_weight=floor_over_weight, final_positions=final,
                        particles_behind_blade=leaked,
                        dp_friction=drucker_prager_friction(soil.friction_angle))
    return result
