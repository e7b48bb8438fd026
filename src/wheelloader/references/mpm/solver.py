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
Results are deterministic for given inputs when Taichi runs on one thread (atomic additions of several
threads can change the rounding order).
"""

# No ``from __future__ import annotations`` here: Taichi reads the kernels' annotations at definition.
import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._backend import taichi_module
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
    """Taichi fields and kernels with fixed capacities (reused across solvers in one process)."""

    def __init__(self, ti: Any, particles: int, nx: int, nz: int) -> None:
        self.ti = ti
        self.particles, self.nx, self.nz = particles, nx, nz
        self.in_use = False
        fb = ti.FieldsBuilder()
        vec2, mat2 = ti.types.vector(2, ti.f32), ti.types.matrix(2, 2, ti.f32)
        self.x = ti.Vector.field(2, ti.f32)
        self.v = ti.Vector.field(2, ti.f32)
        self.C = ti.Matrix.field(2, 2, ti.f32)
        self.F = ti.Matrix.field(2, 2, ti.f32)
        fb.dense(ti.i, particles).place(self.x, self.v, self.C, self.F)
        self.grid_v = ti.Vector.field(2, ti.f32)
        self.grid_m = ti.field(ti.f32)
        fb.dense(ti.ij, (nx, nz)).place(self.grid_v, self.grid_m)
        self.plate_a = ti.Vector.field(2, ti.f32)
        self.plate_b = ti.Vector.field(2, ti.f32)
        self.world_a = ti.Vector.field(2, ti.f32)
        self.world_b = ti.Vector.field(2, ti.f32)
        fb.dense(ti.i, MAX_PLATES).place(self.plate_a, self.plate_b, self.world_a, self.world_b)
        self.impulse = ti.Vector.field(2, ti.f64)
        self.guard_impulse = ti.Vector.field(2, ti.f64)
        self.guarded = ti.field(ti.i64)
        fb.place(self.impulse, self.guard_impulse, self.guarded)
        self.tree = fb.finalize()
        self._build_kernels(ti, vec2, mat2)

    def destroy(self) -> None:
        self.tree.destroy()

    # ---------------------------------------------------------------- kernels
    def _build_kernels(self, ti: Any, vec2: Any, mat2: Any) -> None:  # noqa: C901 - one place for all kernels
        x, v, C, F = self.x, self.v, self.C, self.F
        grid_v, grid_m = self.grid_v, self.grid_m
        plate_a, plate_b = self.plate_a, self.plate_b
        world_a, world_b = self.world_a, self.world_b
        impulse, guard_impulse, guarded = self.impulse, self.guard_impulse, self.guarded
        f32 = ti.f32

        @ti.func
        def clear_grid(nx: ti.i32, nz: ti.i32):
            for i, j in ti.ndrange(nx, nz):
                grid_v[i, j] = vec2(0.0, 0.0)
                grid_m[i, j] = 0.0

        @ti.func
        def cross2(a, b):
            return a[0] * b[1] - a[1] * b[0]

        @ti.func
        def near_tool(xw, n_plates: ti.i32, reach: f32):
            """Whether the world point is within ``reach`` of any plate (then transfers are checked)."""
            near = 0
            for k in range(n_plates):
                a = world_a[k]
                ab = world_b[k] - a
                t = ti.min(ti.max((xw - a).dot(ab) / ab.dot(ab), 0.0), 1.0)
                if (xw - a - t * ab).norm() < reach:
                    near = 1
            return near

        @ti.func
        def blocked(xw, node, n_plates: ti.i32):
            """Index of a plate that the segment particle -> node crosses (CPIC), or -1."""
            hit = -1
            for k in range(n_plates):
                a = world_a[k]
                ab = world_b[k] - a
                d1 = cross2(ab, xw - a)
                d2 = cross2(ab, node - a)
                pq = node - xw
                d3 = cross2(pq, a - xw)
                d4 = cross2(pq, world_b[k] - xw)
                if d1 * d2 < 0.0 and d3 * d4 <= 0.0:
                    hit = k
            return hit

        @ti.func
        def p2g(n: ti.i32, x0: f32, z0: f32, inv_dx: f32, dt: f32, p_vol: f32, p_mass: f32, mu: f32, lam: f32,
                tool_on: ti.i32, n_plates: ti.i32):
            origin = vec2(x0, z0)
            dx = 1.0 / inv_dx
            for p in range(n):
                near = 0
                if tool_on:
                    near = near_tool(x[p], n_plates, 2.5 * dx)
                xp = (x[p] - origin) * inv_dx
                base = ti.cast(xp - 0.5, ti.i32)
                fx = xp - ti.cast(base, f32)
                w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
                U, sig, _V = ti.svd(F[p])
                e0 = ti.log(ti.max(sig[0, 0], 1e-4))
                e1 = ti.log(ti.max(sig[1, 1], 1e-4))
                tr = e0 + e1
                tau = U @ mat2([[2.0 * mu * e0 + lam * tr, 0.0], [0.0, 2.0 * mu * e1 + lam * tr]]) @ U.transpose()
                affine = (-dt * p_vol * 4.0 * inv_dx * inv_dx) * tau + p_mass * C[p]
                for i, j in ti.static(ti.ndrange(3, 3)):
                    offset = ti.Vector([i, j])
                    dpos = (ti.cast(offset, f32) - fx) / inv_dx
                    weight = w[i][0] * w[j][1]
                    ok = 1
                    if near:
                        if blocked(x[p], origin + ti.cast(base + offset, f32) * dx, n_plates) >= 0:
                            ok = 0
                    if ok:
                        grid_v[base + offset] += weight * (p_mass * v[p] + affine @ dpos)
                        grid_m[base + offset] += weight * p_mass
                    else:
                        # the stress (and APIC) impulse this node would have received sums to zero over all
                        # nine nodes; the plate between takes it instead (momentum is conserved)
                        impulse[None] += ti.cast(weight * (affine @ dpos), ti.f64)

        @ti.func
        def body_to_world(b, c, s):
            return vec2(b[0] * c - b[1] * s, b[0] * s + b[1] * c)

        @ti.func
        def world_to_body(d, c, s):
            return vec2(d[0] * c + d[1] * s, -d[0] * s + d[1] * c)

        @ti.func
        def grid_update(nx: ti.i32, nz: ti.i32, x0: f32, z0: f32, dx: f32, dt: f32, gravity: f32, damp: f32,
                        sticky_floor: ti.i32, tool_on: ti.i32, n_plates: ti.i32,
                        tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32,
                        band: f32, tan_delta: f32, adhesion_impulse: f32):
            c0, s0 = ti.cos(a0), ti.sin(a0)
            tip = vec2(tx0, tz0)
            vtip = vec2(tx1 - tx0, tz1 - tz0) / dt
            omega = (a1 - a0) / dt
            for i, j in ti.ndrange(nx, nz):
                m = grid_m[i, j]
                if m > 0.0:
                    vel = grid_v[i, j] / m
                    vel[1] -= dt * gravity
                    vel *= damp
                    if tool_on:
                        rel = vec2(x0 + i * dx, z0 + j * dx) - tip
                        q = world_to_body(rel, c0, s0)
                        best = band
                        nb = vec2(0.0, 0.0)
                        for k in range(n_plates):
                            a = plate_a[k]
                            ab = plate_b[k] - a
                            l2 = ab.dot(ab)
                            t = (q - a).dot(ab) / l2
                            d = q - (a + t * ab)
                            dist = d.norm()
                            if dist < best and 0.0 <= t <= 1.0:
                                best = dist
                                if dist > 1e-6 * dx:
                                    nb = d / dist
                                else:
                                    nb = vec2(-ab[1], ab[0]) / ti.sqrt(l2)
                        if best < band:
                            nrm = body_to_world(nb, c0, s0)
                            vt = vtip + omega * vec2(-rel[1], rel[0])
                            r = vel - vt
                            vn = r.dot(nrm)
                            if vn < 0.0:
                                tang = r - vn * nrm
                                tl = tang.norm()
                                cap = tan_delta * (-vn) + adhesion_impulse / m
                                if tl <= cap:
                                    tang = vec2(0.0, 0.0)
                                else:
                                    tang *= 1.0 - cap / tl
                                new = vt + tang
                                dv = vel - new
                                impulse[None] += ti.cast(m, ti.f64) * ti.cast(dv, ti.f64)
                                vel = new
                    if i <= 2 and vel[0] < 0.0:
                        vel[0] = 0.0
                    if i >= nx - 3 and vel[0] > 0.0:
                        vel[0] = 0.0
                    if j <= 2:
                        if sticky_floor:
                            vel = vec2(0.0, 0.0)
                        elif vel[1] < 0.0:
                            vel[1] = 0.0
                    if j >= nz - 3 and vel[1] > 0.0:
                        vel[1] = 0.0
                    grid_v[i, j] = vel

        @ti.func
        def g2p(n: ti.i32, x0: f32, z0: f32, inv_dx: f32, dt: f32, p_mass: f32, mu: f32, lam: f32, sin_phi: f32,
                cos_phi: f32,
                cohesion: f32, tool_on: ti.i32, n_plates: ti.i32,
                tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32, guard: f32,
                x_lo: f32, x_hi: f32, z_lo: f32, z_hi: f32):
            origin = vec2(x0, z0)
            c0, s0 = ti.cos(a0), ti.sin(a0)
            c1, s1 = ti.cos(a1), ti.sin(a1)
            tip0 = vec2(tx0, tz0)
            tip1 = vec2(tx1, tz1)
            vtip = (tip1 - tip0) / dt
            omega = (a1 - a0) / dt
            dx = 1.0 / inv_dx
            for p in range(n):
                near = 0
                if tool_on:
                    near = near_tool(x[p], n_plates, 2.5 * dx)
                xp = (x[p] - origin) * inv_dx
                base = ti.cast(xp - 0.5, ti.i32)
                fx = xp - ti.cast(base, f32)
                w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
                new_v = vec2(0.0, 0.0)
                new_c = mat2([[0.0, 0.0], [0.0, 0.0]])
                for i, j in ti.static(ti.ndrange(3, 3)):
                    offset = ti.Vector([i, j])
                    dpos = ti.cast(offset, f32) - fx
                    g = grid_v[base + offset]
                    if near:
                        k = blocked(x[p], origin + ti.cast(base + offset, f32) * dx, n_plates)
                        if k >= 0:
                            # a node across a plate: the particle's own velocity, not moving into the plate
                            a = world_a[k]
                            ab = world_b[k] - a
                            nrm = vec2(-ab[1], ab[0]).normalized()
                            if cross2(ab, x[p] - a) < 0.0:
                                nrm = -nrm
                            rel = x[p] - tip0
                            r = v[p] - (vtip + omega * vec2(-rel[1], rel[0]))
                            rn = r.dot(nrm)
                            g = v[p]
                            if rn < 0.0:
                                g = v[p] - rn * nrm
                    weight = w[i][0] * w[j][1]
                    new_v += weight * g
                    new_c += 4.0 * inv_dx * weight * g.outer_product(dpos)
                # elastic predictor and Mohr-Coulomb return mapping in log-strain space
                f_new = (ti.Matrix.identity(f32, 2) + dt * new_c) @ F[p]
                U, sig, V = ti.svd(f_new)
                e0 = ti.log(ti.max(sig[0, 0], 1e-4))
                e1 = ti.log(ti.max(sig[1, 1], 1e-4))
                tr = e0 + e1
                p_mean = (lam + mu) * tr
                q_dev = mu * ti.abs(e0 - e1)
                if sin_phi > 1e-6 and p_mean * sin_phi >= cohesion * cos_phi:
                    e_apex = cohesion * cos_phi / sin_phi / (2.0 * (lam + mu))
                    e0 = e_apex
                    e1 = e_apex
                else:
                    limit = cohesion * cos_phi - p_mean * sin_phi
                    if q_dev > limit:
                        half = 0.5 * (e0 - e1) * limit / q_dev
                        e0 = 0.5 * tr + half
                        e1 = 0.5 * tr - half
                F[p] = U @ mat2([[ti.exp(e0), 0.0], [0.0, ti.exp(e1)]]) @ V.transpose()
                C[p] = new_c
                x_old = x[p]
                x_new = x_old + dt * new_v
                if tool_on:
                    for k in range(n_plates):
                        a = plate_a[k]
                        ab = plate_b[k] - a
                        length = ab.norm()
                        q_old = world_to_body(x_old - tip0, c0, s0) - a
                        q_new = world_to_body(x_new - tip1, c1, s1) - a
                        t_old = q_old.dot(ab) / (length * length)
                        t_new = q_new.dot(ab) / (length * length)
                        w_old = (ab[0] * q_old[1] - ab[1] * q_old[0]) / length
                        w_new = (ab[0] * q_new[1] - ab[1] * q_new[0]) / length
                        if 0.0 <= t_old <= 1.0 and 0.0 <= t_new <= 1.0:
                            if w_old * w_new < 0.0 or ti.abs(w_new) < guard:
                                side = 1.0
                                if w_old < 0.0:
                                    side = -1.0
                                perp = vec2(-ab[1], ab[0]) / length
                                q_fix = a + t_new * ab + side * guard * perp
                                x_new = tip1 + body_to_world(q_fix, c1, s1)
                                nrm = side * body_to_world(perp, c1, s1)
                                rel = x_new - tip1
                                r = new_v - (vtip + omega * vec2(-rel[1], rel[0]))
                                rn = r.dot(nrm)
                                if rn < 0.0:
                                    new_v -= rn * nrm
                                    guard_impulse[None] += ti.cast(p_mass * rn * nrm, ti.f64)
                                guarded[None] += 1
                x_new[0] = ti.min(ti.max(x_new[0], x_lo), x_hi)
                x_new[1] = ti.min(ti.max(x_new[1], z_lo), z_hi)
                v[p] = new_v
                x[p] = x_new

        @ti.kernel
        def reset_counters():
            impulse[None] = ti.Vector([0.0, 0.0], ti.f64)
            guard_impulse[None] = ti.Vector([0.0, 0.0], ti.f64)
            guarded[None] = 0

        @ti.kernel
        def substep(n: ti.i32, nx: ti.i32, nz: ti.i32, x0: f32, z0: f32, dx: f32, dt: f32, p_vol: f32, p_mass: f32,
                    mu: f32, lam: f32, sin_phi: f32, cos_phi: f32, cohesion: f32, gravity: f32, damp: f32,
                    sticky_floor: ti.i32, tool_on: ti.i32, n_plates: ti.i32,
                    tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32,
                    band: f32, tan_delta: f32, adhesion_impulse: f32, guard: f32,
                    x_lo: f32, x_hi: f32, z_lo: f32, z_hi: f32):
            inv_dx = 1.0 / dx
            c0, s0 = ti.cos(a0), ti.sin(a0)
            for k in range(n_plates):
                world_a[k] = vec2(tx0, tz0) + body_to_world(plate_a[k], c0, s0)
                world_b[k] = vec2(tx0, tz0) + body_to_world(plate_b[k], c0, s0)
            clear_grid(nx, nz)
            p2g(n, x0, z0, inv_dx, dt, p_vol, p_mass, mu, lam, tool_on, n_plates)
            grid_update(nx, nz, x0, z0, dx, dt, gravity, damp, sticky_floor, tool_on, n_plates, tx0, tz0, a0, tx1, tz1,
                        a1, band, tan_delta, adhesion_impulse)
            g2p(n, x0, z0, inv_dx, dt, p_mass, mu, lam, sin_phi, cos_phi, cohesion, tool_on, n_plates, tx0, tz0, a0,
                tx1, tz1, a1, guard, x_lo, x_hi, z_lo, z_hi)

        self.substep = substep
        self.reset_counters = reset_counters


_POOL: list[_Fields] = []


def _acquire_fields(ti: Any, particles: int, nx: int, nz: int) -> _Fields:
    for fields in _POOL:
        if not fields.in_use and fields.particles >= particles and fields.nx >= nx and fields.nz >= nz:
            fields.in_use = True
            return fields
    # grow with spare room so that slightly larger scenes reuse the allocation (and the compiled kernels)
    cap_p = int(math.ceil(particles * 1.25 / 4096.0)) * 4096
    cap_x = int(math.ceil(nx * 1.1 / 16.0)) * 16
    cap_z = int(math.ceil(nz * 1.1 / 16.0)) * 16
    for old in [f for f in _POOL if not f.in_use]:
        cap_p, cap_x, cap_z = max(cap_p, old.particles), max(cap_x, old.nx), max(cap_z, old.nz)
        old.destroy()
        _POOL.remove(old)
    fields = _Fields(ti, cap_p, cap_x, cap_z)
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
        Taichi CPU threads (used at the process's first Taichi initialisation only).
    """

    def __init__(self, soil: ContinuumSoil, domain: Domain, dx: float, particles: np.ndarray, *,
                 tool: ToolShape | None = None, contact_band: float = 1.0, cfl: float = 0.3,
                 sticky_floor: bool = True, threads: int = 1) -> None:
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
        ti = taichi_module(threads)
        self._ti = ti
        self._f = _acquire_fields(ti, self.n, self.nx, self.nz)
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
        f.reset_counters()

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
        before = f.impulse.to_numpy().astype(float) + f.guard_impulse.to_numpy().astype(float)
        for k in range(steps):
            pose = (float(px[k]), float(pz[k]), float(pa[k]), float(px[k + 1]), float(pz[k + 1]), float(pa[k + 1]))
            f.substep(*head, *pose, *tail)
        self.time = float(t_end)
        self.steps += steps
        return f.impulse.to_numpy().astype(float) + f.guard_impulse.to_numpy().astype(float) - before

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
        return self._f.impulse.to_numpy().astype(float) + self.guard_impulse

    @property
    def guard_impulse(self) -> np.ndarray:
        """Part of the tool impulse so far [N s per m] that came through the particle guard."""
        return self._f.guard_impulse.to_numpy().astype(float)

    @property
    def guard_corrections(self) -> int:
        """Particle-steps corrected by the plate guard so far."""
        return int(self._f.guarded.to_numpy())

    def close(self) -> None:
        """Give the fields back to the process's pool (the solver is unusable afterwards)."""
        self._finalizer()

    def __enter__(self) -> "MPMSolver":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
