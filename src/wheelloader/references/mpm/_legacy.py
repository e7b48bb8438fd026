"""The solver's kernels as they were before the single-thread rewrite (``MPMSolver(..., legacy=True)``).

Kept callable so that ``benchmarks/mpm_speed.py`` can run the old and the new solver side by side in one
invocation, and tests can hold the new kernels to the old ones. The mathematics is the module
docstring of :mod:`.solver`; this code is the old one unchanged but for where it finds its fields: the
grid is ``grid_v``/``grid_m`` (cleared every step), the stress comes from an SVD of ``F`` in
particle -> grid, and every scatter is an atomic addition (Taichi compiles atomics even on one thread).
The tool impulse and guard counters are the 0-D fields ``impulse``, ``guard_impulse``, ``guarded`` (Taichi
accumulates such scalars per thread block first, so their rounding differs from the lanes' counters).
"""

# No ``from __future__ import annotations`` here: Taichi reads the kernels' annotations at definition.
from typing import Any


def build_legacy_kernels(fields: Any) -> tuple[Any, Any]:  # noqa: C901 - the old kernels in one place
    """Compile-on-first-call kernels ``(substep, reset_counters)`` of the old solver on ``fields``."""
    ti = fields.ti
    vec2, mat2 = ti.types.vector(2, ti.f32), ti.types.matrix(2, 2, ti.f32)
    x, v, C, F = fields.x, fields.v, fields.C, fields.F
    grid_v, grid_m = fields.grid_v, fields.grid_m
    plate_a, plate_b = fields.plate_a, fields.plate_b
    world_a, world_b = fields.world_a, fields.world_b
    impulse, guard_impulse, guarded = fields.impulse, fields.guard_impulse, fields.guarded
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

    return substep, reset_counters
