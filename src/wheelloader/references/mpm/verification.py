"""Verification cases of the solver against closed-form soil mechanics (each a few solver seconds).

* :func:`run_blade`: a vertical blade pushed through a flat soil bed, against :func:`mckyes_blade`
  (the McKyes / Fundamental Earthmoving Equation passive wedge);
* :func:`run_wall`: a frictionless wall against a soil block, at rest (against the elastic / Jaky
  at-rest ratio) and pushed into it (against Rankine's passive pressure, :func:`rankine_passive`);
* :func:`run_column_collapse`: a granular column collapsing on a rough floor, against the run-out
  scaling of Lube et al. (2005), :func:`column_runout_scaling`.

The benchmark ``benchmarks/mpm_verification.py`` runs them and writes the report.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .scene import fill_particles
from .soil import ContinuumSoil
from .solver import GRAVITY, PARTICLES_PER_CELL, Domain, MPMSolver
from .tool import Plate, ToolShape, Trajectory


# ------------------------------------------------------------------ closed forms
def mckyes_blade(depth: float, soil: ContinuumSoil, rake: float = math.pi / 2, surcharge: float = 0.0
                 ) -> dict[str, float]:
    """Passive-wedge force of a wide blade per metre of width (McKyes 1985; the FEE of the force model).

    ``P = gamma g d^2 N_gamma + c d N_c + c_a d N_a + q d N_q`` minimised over the failure-plane angle
    beta, for a blade of ``rake`` [rad] (pi/2: vertical) cutting ``depth`` [m] into a flat surface;
    P acts at delta to the blade normal, so the horizontal part is ``P sin(rake + delta)`` and the
    vertical ``P cos(rake + delta)``.

    Returns
    -------
    dict
        ``total`` P, ``horizontal``, ``vertical`` [N/m] and ``beta`` [rad].
    """
    if not depth > 0.0:
        raise ValueError(f"depth must be > 0 m, got {depth!r}")
    phi, delta = soil.friction_angle, soil.wall_friction_angle
    gamma = soil.density * GRAVITY
    beta = np.linspace(math.radians(5.0), math.radians(85.0), 16001)
    cot = lambda a: np.cos(a) / np.sin(a)
    den = math.cos(rake + delta) + math.sin(rake + delta) * cot(beta + phi)
    cot_rake = math.cos(rake) / math.sin(rake)
    n_gamma = (cot_rake + cot(beta)) / (2.0 * den)
    n_c = (1.0 + cot(beta) * cot(beta + phi)) / den
    n_a = (1.0 - cot_rake * cot(beta + phi)) / den
    n_q = (cot_rake + cot(beta)) / den
    total = gamma * depth**2 * n_gamma + soil.cohesion * depth * n_c + soil.adhesion * depth * n_a \
        + surcharge * depth * n_q
    total = np.where(den > 0.0, total, np.inf)
    k = int(np.argmin(total))
    p = float(total[k])
    return {"total": p, "horizontal": p * math.sin(rake + delta), "vertical": p * math.cos(rake + delta),
            "beta": float(beta[k])}


def mckyes_blade_with_heap(depth: float, soil: ContinuumSoil, heap_ahead: Callable[[float], float],
                           iterations: int = 20) -> dict[str, float]:
    """The McKyes wedge of a vertical blade carrying the soil heaped on it as its surcharge ``q``.

    The FEE's surcharge term ``q d N_q`` stands for the weight of soil lying on the failure wedge, i.e.
    ``q = W / L`` with ``W`` the heaped mass x g over the wedge's top length ``L = d cot(beta)``. ``L``
    depends on the critical beta and beta on ``q``, so the two are iterated to a fixed point.

    Parameters
    ----------
    depth : float
        Cut depth [m].
    soil : ContinuumSoil
        The soil (phi, delta, c, c_a, density).
    heap_ahead : callable
        ``heap_ahead(L)``: the heaped mass [kg per metre of width] above the original surface within a
        distance ``L`` [m] ahead of the blade (measured in the simulation).
    iterations : int
        Fixed-point iterations (the change is below 0.1 % after a handful).

    Returns
    -------
    dict
        As :func:`mckyes_blade`, plus ``surcharge`` q [Pa] and ``wedge_length`` L [m].
    """
    ref = mckyes_blade(depth, soil)
    q = 0.0
    length = depth / math.tan(ref["beta"])
    for _ in range(iterations):
        length = depth / math.tan(ref["beta"])
        q = GRAVITY * float(heap_ahead(length)) / length
        ref = mckyes_blade(depth, soil, surcharge=q)
    return {**ref, "surcharge": q, "wedge_length": length}


def rankine_passive(height: float, soil: ContinuumSoil) -> float:
    """Rankine passive force on a smooth vertical wall [N/m]: ``K_p gamma g H^2 / 2 + 2 c sqrt(K_p) H``."""
    kp = (1.0 + math.sin(soil.friction_angle)) / (1.0 - math.sin(soil.friction_angle))
    return 0.5 * kp * soil.density * GRAVITY * height**2 + 2.0 * soil.cohesion * math.sqrt(kp) * height


def at_rest_force(height: float, soil: ContinuumSoil, ratio: float | None = None) -> float:
    """At-rest force on a vertical wall [N/m]: ``K0 gamma g H^2 / 2`` (K0 default: Jaky, 1 - sin(phi))."""
    k0 = 1.0 - math.sin(soil.friction_angle) if ratio is None else ratio
    return 0.5 * k0 * soil.density * GRAVITY * height**2


def column_runout_true_2d(aspect_ratio: float) -> float | None:
    """Normalised run-out ``(L_inf - L_0) / L_0`` of the true-2-D experiments with aluminium rods.

    The fits of arXiv:1512.05180 (2015, "Failure mechanism of true 2D granular flows"): ``3.25 a^0.96`` for
    0.65 < a < 1.5 and ``3.80 a^0.73`` for a > 1.5; below a = 0.65 the column keeps its height and the
    paper gives no run-out law (None). Quasi-2-D channels (:func:`column_runout_scaling`) run out less:
    the channel walls' friction; together they bracket the published 2-D data.
    """
    a = float(aspect_ratio)
    if not a > 0.0:
        raise ValueError(f"aspect_ratio must be > 0, got {aspect_ratio!r}")
    if a <= 0.65:
        return None
    return 3.25 * a**0.96 if a < 1.5 else 3.80 * a**0.73


def column_runout_scaling(aspect_ratio: float) -> dict[str, float | str]:
    """Normalised run-out ``(L_inf - L_0) / L_0`` of a 2-D granular column of ``aspect_ratio`` a = H0/L0.

    The fits of Lube et al. (2005, Phys. Rev. E 72, 041301; quasi-2D channel): ``1.2 a`` for a < 1.8 and
    ``1.9 a^(2/3)`` for a > 2.8; between them the two fits are interpolated linearly in a.
    """
    a = float(aspect_ratio)
    if not a > 0.0:
        raise ValueError(f"aspect_ratio must be > 0, got {aspect_ratio!r}")
    if a < 1.8:
        return {"lube": 1.2 * a, "regime": "1.2 a"}
    if a > 2.8:
        return {"lube": 1.9 * a ** (2.0 / 3.0), "regime": "1.9 a^(2/3)"}
    w = (a - 1.8) / 1.0
    return {"lube": (1.0 - w) * 1.2 * a + w * 1.9 * a ** (2.0 / 3.0), "regime": "transition (interpolated)"}


# ------------------------------------------------------------------ simulations
@dataclass
class CaseResult:
    """Time series of one verification run (forces per metre of width)."""

    times: np.ndarray
    force: np.ndarray
    particles: int
    steps: int
    wall_s: float
    extra: dict[str, float] = field(default_factory=dict)


def _ramp(t: np.ndarray, speed: float, ramp: float) -> np.ndarray:
    """Displacement of a motion that reaches ``speed`` over ``ramp`` seconds (smoothstep acceleration)."""
    u = np.clip(t / ramp, 0.0, 1.0)
    # integral of speed * (3u^2 - 2u^3) for t < ramp, then constant speed
    inside = speed * ramp * (u**3 - 0.5 * u**4)
    return np.where(t < ramp, inside, speed * ramp * 0.5 + speed * (t - ramp))


def _run(solver: MPMSolver, trajectory: Trajectory | None, settle: float, duration: float, samples: int,
         damping: float = 20.0, observe: Callable[[MPMSolver, float], None] | None = None
         ) -> tuple[np.ndarray, np.ndarray]:
    solver.time = -settle
    if settle > 0.0:
        solver.advance(0.0, trajectory, damping=damping)
    times = np.linspace(0.0, duration, samples + 1)
    force = np.zeros((samples, 2))
    for k in range(samples):
        force[k] = solver.advance(times[k + 1], trajectory) / (times[k + 1] - times[k])
        if observe is not None:
            observe(solver, float(times[k + 1]))
    return 0.5 * (times[1:] + times[:-1]), force


BLADE_RAMP_S = 0.1


def blade_motion(depth: float, speed: float = 0.2, travel: float | None = None
                 ) -> tuple[float, float, Callable[[np.ndarray | float], np.ndarray]]:
    """The blade motion of the verification case: ``(travel, duration, position)``.

    ``travel`` defaults to 1.2 ``depth``; the blade reaches ``speed`` over :data:`BLADE_RAMP_S` with a
    smoothstep acceleration, ``duration = ramp / 2 + travel / speed``; ``position(t)`` is the
    displacement [m] at ``t`` [s] (0 before the start).
    """
    travel = 1.2 * depth if travel is None else travel
    duration = BLADE_RAMP_S / 2 + travel / speed
    return travel, duration, lambda t: _ramp(np.clip(np.asarray(t, dtype=float), 0.0, None), speed, BLADE_RAMP_S)


def run_blade(depth: float, soil: ContinuumSoil, dx: float, *, speed: float = 0.2, travel: float | None = None,
              contact_band: float = 1.0, seed: int = 0, threads: int = 1, samples_per_s: float = 60.0,
              legacy: bool = False, elastic_f: str = "exact") -> CaseResult:
    """A vertical blade ``depth`` [m] deep pushed at ``speed`` [m/s] through a flat bed.

    The bed is ``depth + max(0.1, depth)`` deep on a sticky floor, long enough for the travel plus three
    wedge lengths; no soil behind the blade. Returns the force on the blade (x: soil pushing it back is
    negative) at ``samples_per_s`` and ``extra['travel']`` per sample [m].
    """
    import time

    travel, duration, _ = blade_motion(depth, speed, travel)
    ramp = BLADE_RAMP_S
    below = max(0.1, depth)
    surface = depth + below
    x_blade = 0.0
    x_end = x_blade + travel + 4.0 * depth + 0.1
    spacing = dx / PARTICLES_PER_CELL
    rng = np.random.default_rng(seed)
    pts, over = fill_particles(lambda x: np.full_like(np.asarray(x, dtype=float), surface), x_blade + 0.5 * spacing,
                               x_end, 0.0, spacing, rng)
    height = depth + 0.3
    blade = ToolShape((Plate((0.0, 0.0), (0.0, height)),))
    domain = Domain(x_blade - 0.1, 0.0, x_end, surface + height)
    t = np.linspace(-1.0, duration + 0.01, 4001)
    xs = x_blade + _ramp(np.clip(t, 0.0, None), speed, ramp)
    traj = Trajectory(t, xs, np.full_like(t, below), np.zeros_like(t))
    # the heap: soil above the original surface, binned by distance ahead of the blade (mass per metre)
    heap_bins = np.arange(0.0, x_end - x_blade + dx, dx)
    heap: list[np.ndarray] = []

    def observe_heap(solver: MPMSolver, t: float) -> None:
        p = solver.positions()
        ahead = p[:, 0] - float(np.interp(t, traj.t, traj.x))
        above = p[:, 1] > surface
        counts, _ = np.histogram(ahead[above], bins=heap_bins)
        heap.append(counts * solver.particle_mass)

    wall0 = time.perf_counter()
    with MPMSolver(soil, domain, dx, pts, tool=blade, contact_band=contact_band, threads=threads,
                   legacy=legacy, elastic_f=elastic_f) as solver:
        solver.set_geostatic_stress(over)
        times, force = _run(solver, traj, 0.2, duration, int(round(duration * samples_per_s)), observe=observe_heap)
        steps = solver.steps
        guard_share = float(np.linalg.norm(solver.guard_impulse) / max(1e-12, np.linalg.norm(solver.total_impulse)))
        guard_count = solver.guard_corrections
    wall = time.perf_counter() - wall0
    result = CaseResult(times, force, len(pts), steps, wall)
    result.extra["travel"] = _ramp(times, speed, ramp)
    result.extra["heap_mass"] = np.array(heap)
    result.extra["heap_bin_edges"] = heap_bins
    result.extra.update(guard_impulse_share=guard_share, guard_corrections=guard_count)
    return result


def run_wall(height: float, soil: ContinuumSoil, dx: float, *, push: float = 0.0, speed: float = 0.05,
             length: float | None = None, rest: float = 0.6, seed: int = 0, threads: int = 1,
             legacy: bool = False, elastic_f: str = "exact") -> CaseResult:
    """A smooth vertical wall (no friction, no adhesion) against a soil block ``height`` [m] high.

    The block starts stress-free and settles under gravity for ``rest`` [s] against the fixed wall on a
    frictionless floor (at-rest state); then, if ``push`` > 0, the wall moves ``push`` [m] into it at
    ``speed`` [m/s] (passive state). Returns the wall force (x component > 0 pushes the wall back... of
    sign: negative x = soil pushing the wall toward -x).
    """
    import time

    length = 4.0 * height if length is None else length
    wall_soil = ContinuumSoil(soil.density, soil.friction_angle, soil.cohesion, 0.0, 0.0, soil.youngs_modulus,
                              soil.poisson_ratio)
    spacing = dx / PARTICLES_PER_CELL
    rng = np.random.default_rng(seed)
    pts, _ = fill_particles(lambda x: np.full_like(np.asarray(x, dtype=float), height), 0.5 * spacing, length, 0.0,
                            spacing, rng)
    plate = ToolShape((Plate((0.0, 0.0), (0.0, height + 0.3)),))
    domain = Domain(-0.1, 0.0, length, 2.0 * height + 0.3)
    ramp = 0.1
    duration = rest + (push / speed + ramp / 2 if push > 0 else 0.0)
    t = np.linspace(-1.0, duration + 0.01, 4001)
    xs = -0.25 * dx + (_ramp(np.clip(t - rest, 0.0, None), speed, ramp) if push > 0 else 0.0 * t)
    traj = Trajectory(t, xs, np.zeros_like(t), np.zeros_like(t))
    wall0 = time.perf_counter()
    with MPMSolver(wall_soil, domain, dx, pts, tool=plate, sticky_floor=False, threads=threads,
                   legacy=legacy, elastic_f=elastic_f) as solver:
        solver.time = 0.0
        samples = int(round(duration * 60))
        times = np.linspace(0.0, duration, samples + 1)
        force = np.zeros((samples, 2))
        for k in range(samples):
            damping = 20.0 if times[k] < rest else 0.0
            force[k] = solver.advance(times[k + 1], traj, damping=damping) / (times[k + 1] - times[k])
        steps = solver.steps
    wall = time.perf_counter() - wall0
    result = CaseResult(0.5 * (times[1:] + times[:-1]), force, len(pts), steps, wall)
    result.extra["displacement"] = np.interp(result.times, t, xs) - xs[0]
    return result


def run_column_collapse(aspect_ratio: float, soil: ContinuumSoil, dx: float, *, width: float = 0.2,
                        duration: float | None = None, seed: int = 0, threads: int = 1,
                        legacy: bool = False) -> CaseResult:
    """A column ``width`` [m] wide and ``aspect_ratio * width`` high released against a smooth wall.

    The column stands at a frictionless wall (the symmetry plane of the experiments' half-columns) on
    a rough (sticky) floor and starts at its geostatic state. Returns ``extra['runout']`` = ``(L_inf -
    L_0) / L_0`` with ``L_inf`` the furthest particle resting on the floor at the end.
    """
    import time

    h0 = aspect_ratio * width
    duration = max(1.0, 4.0 * math.sqrt(h0 / GRAVITY) + 0.6) if duration is None else duration
    spacing = dx / PARTICLES_PER_CELL
    rng = np.random.default_rng(seed)
    pts, over = fill_particles(lambda x: np.full_like(np.asarray(x, dtype=float), h0), 0.0, width, 0.0, spacing, rng)
    reach = width * (1.0 + 3.0 * float(column_runout_scaling(aspect_ratio)["lube"])) + 0.1
    domain = Domain(0.0, 0.0, reach, h0 + 0.1)
    wall0 = time.perf_counter()
    with MPMSolver(soil, domain, dx, pts, threads=threads, legacy=legacy) as solver:
        solver.set_geostatic_stress(over)
        samples = int(round(duration * 20))
        times, force = _run(solver, None, 0.0, duration, samples)
        end = solver.positions()
        ke = solver.kinetic_energy()
        steps = solver.steps
    wall = time.perf_counter() - wall0
    # the front: furthest x where the deposit is at least one particle thick (ignores lone grains)
    bins = np.arange(0.0, reach + spacing, spacing)
    counts, _ = np.histogram(end[:, 0], bins=bins)
    occupied = np.flatnonzero(counts >= 2)
    front = float(bins[occupied[-1] + 1]) if occupied.size else width
    result = CaseResult(times, force, len(pts), steps, wall)
    result.extra.update(runout=(front - width) / width, final_height=float(end[:, 1].max()), kinetic_energy=ke)
    return result
