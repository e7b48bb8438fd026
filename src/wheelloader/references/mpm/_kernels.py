"""The solver's kernels: the step of :mod:`.solver` without atomic additions on the CPU.

The mathematics is the module docstring of :mod:`.solver`; this is how it is laid out for speed.

* **Lanes instead of atomics (CPU).** Taichi compiles ``field[i] += value`` in a parallel loop as an
  atomic addition, and on the CPU a float atomic is a compare-and-swap loop even when Taichi runs on
  one thread (the particle -> grid scatter cost 8.5 ms per step against 0.6 ms without). Here the
  particles are split into ``lanes`` contiguous blocks; each lane scatters its block in order into its
  own copy of the grid with plain loads and stores, and the grid update adds the lanes (in lane order)
  and clears them. Lanes run in parallel, one per thread, so the result depends on the lane count and
  never on thread scheduling: it is deterministic for any number of threads. The tool impulse and the
  guard counters are per lane too (summed when read).
* **Atomic scatter (GPU).** With ``atomic=True`` the loops are parallel over particles and nodes and
  the scatter is atomic (one lane), as GPUs want it.
* **One SVD per particle and step.** The Kirchhoff stress is computed where the return mapping already
  has the singular values (grid -> particle) and kept per particle (``tau``) for the next
  particle -> grid, instead of a second SVD of ``F`` there.
* **The tool's box.** Particles and nodes outside the axis-aligned box of the plates (widened by the
  largest reach the contact, the transfer check or the guard can have) skip the per-plate loops: they
  would find no plate within reach.
* **Few kernel arguments.** A call with 33 arguments costs Taichi about 0.1 ms; the step's settings go to
  small fields once per :meth:`~.solver.MPMSolver.advance` and its tool poses in chunks, so a step is
  called with its index only.
* **Near-tool flags.** Whether a particle is near the tool is decided once per step (particle -> grid)
  and reused in grid -> particle (the particle has not moved in between).
* **The elastic F kept as computed.** A particle that stays elastic keeps ``F = (I + dt C) F`` as
  multiplied; a plastic one gets its stretches scaled in place. The old kernels rebuilt every ``F`` from
  its SVD, ``U exp(log sigma) V^T``, every step; with ``svd_f=True`` these kernels do that too (the
  return mapping then on the SVD's stretches), for comparisons only
  (``docs/results/mpm_reproducibility.md``: that rounding makes the smooth wall's at-rest force creep).
"""

# No ``from __future__ import annotations`` here: Taichi reads the kernels' annotations at definition.
from typing import Any

#: Reach [cells] within which a particle checks its transfers against the plates (CPIC).
TRANSFER_REACH = 2.5
#: The integer settings of a step, in the order of the ``iparam`` field.
INT_PARAMS = ("n", "nx", "nz", "sticky_floor", "tool_on", "n_plates")
#: The float settings of a step, in the order of the ``fparam`` field.
FLOAT_PARAMS = ("x0", "z0", "dx", "dt", "p_vol", "p_mass", "mu", "lam", "sin_phi", "cos_phi", "cohesion", "gravity",
                "damp", "band", "tan_delta", "adhesion_impulse", "guard", "x_lo", "x_hi", "z_lo", "z_hi")
#: Steps per upload of tool poses (a longer advance uploads its poses in chunks).
POSE_CHUNK = 1024


def build_kernels(fields: Any, lanes: int, atomic: bool,  # noqa: C901 - the kernels in one place
                  svd_f: bool = False) -> tuple[Any, Any, Any]:
    """Kernels ``(substep, reset_counters, init_stress)`` on ``fields`` for ``lanes`` lanes.

    ``atomic``: parallel loops with atomic scatter (GPU backends; ``lanes`` must be 1). ``svd_f``: rebuild
    every particle's ``F`` from its SVD each step, as the old kernels did (for comparisons).
    """
    ti = fields.ti
    vec2, mat2 = ti.types.vector(2, ti.f32), ti.types.matrix(2, 2, ti.f32)
    f32 = ti.f32
    x, v, C, F, tau, near_flag = fields.x, fields.v, fields.C, fields.F, fields.tau, fields.near_flag
    grid_v, lane_v, lane_m = fields.grid_v, fields.lane_v, fields.lane_m
    plate_a, plate_b = fields.plate_a, fields.plate_b
    world_a, world_b, box = fields.world_a, fields.world_b, fields.box
    impulse, guard_impulse, guarded = fields.lane_impulse, fields.lane_guard_impulse, fields.lane_guarded
    iparam, fparam, pose = fields.iparam, fields.fparam, fields.pose

    @ti.func
    def add_to(field, index, value):
        if ti.static(atomic):
            field[index] += value
        else:
            field[index] = field[index] + value

    @ti.func
    def in_box(xw, which: ti.i32, reach: f32):
        b = box[which]
        return b[0] - reach <= xw[0] <= b[2] + reach and b[1] - reach <= xw[1] <= b[3] + reach

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
    def body_to_world(b, c, s):
        return vec2(b[0] * c - b[1] * s, b[0] * s + b[1] * c)

    @ti.func
    def world_to_body(d, c, s):
        return vec2(d[0] * c + d[1] * s, -d[0] * s + d[1] * c)

    @ti.func
    def kirchhoff(U, e0, e1, mu: f32, lam: f32):
        tr = e0 + e1
        return U @ mat2([[2.0 * mu * e0 + lam * tr, 0.0], [0.0, 2.0 * mu * e1 + lam * tr]]) @ U.transpose()

    @ti.func
    def return_mapping(f0, f1, mu: f32, lam: f32, sin_phi: f32, cos_phi: f32, cohesion: f32):
        """Mohr-Coulomb return mapping of the log stretches ``(f0, f1)``: the returned ones and whether it
        yielded (the module docstring of :mod:`.solver`)."""
        e0, e1 = f0, f1
        tr = e0 + e1
        p_mean = (lam + mu) * tr
        q_dev = mu * ti.abs(e0 - e1)
        plastic = 0
        if sin_phi > 1e-6 and p_mean * sin_phi >= cohesion * cos_phi:
            e_apex = cohesion * cos_phi / sin_phi / (2.0 * (lam + mu))
            e0 = e_apex
            e1 = e_apex
            plastic = 1
        else:
            limit = cohesion * cos_phi - p_mean * sin_phi
            if q_dev > limit:
                half = 0.5 * (e0 - e1) * limit / q_dev
                e0 = 0.5 * tr + half
                e1 = 0.5 * tr - half
                plastic = 1
        return e0, e1, plastic

    # ------------------------------------------------------------ particle -> grid
    @ti.func
    def p2g_one(p: ti.i32, lane: ti.i32, origin, inv_dx: f32, dt: f32, p_vol: f32, p_mass: f32, tool_on: ti.i32,
                n_plates: ti.i32):
        dx = 1.0 / inv_dx
        reach = TRANSFER_REACH * dx
        near = 0
        if tool_on:
            if in_box(x[p], 0, reach):
                near = near_tool(x[p], n_plates, reach)
        near_flag[p] = near
        xp = (x[p] - origin) * inv_dx
        base = ti.cast(xp - 0.5, ti.i32)
        fx = xp - ti.cast(base, f32)
        w = [0.5 * (1.5 - fx) ** 2, 0.75 - (fx - 1.0) ** 2, 0.5 * (fx - 0.5) ** 2]
        affine = (-dt * p_vol * 4.0 * inv_dx * inv_dx) * tau[p] + p_mass * C[p]
        for i, j in ti.static(ti.ndrange(3, 3)):
            offset = ti.Vector([i, j])
            dpos = (ti.cast(offset, f32) - fx) / inv_dx
            weight = w[i][0] * w[j][1]
            ok = 1
            if near:
                if blocked(x[p], origin + ti.cast(base + offset, f32) * dx, n_plates) >= 0:
                    ok = 0
            if ok:
                add_to(lane_v, (lane, base[0] + i, base[1] + j), weight * (p_mass * v[p] + affine @ dpos))
                add_to(lane_m, (lane, base[0] + i, base[1] + j), weight * p_mass)
            else:
                # the stress (and APIC) impulse this node would have received sums to zero over all
                # nine nodes; the plate between takes it instead (momentum is conserved)
                add_to(impulse, lane, ti.cast(weight * (affine @ dpos), ti.f64))

    @ti.func
    def p2g(n: ti.i32, x0: f32, z0: f32, inv_dx: f32, dt: f32, p_vol: f32, p_mass: f32, tool_on: ti.i32,
            n_plates: ti.i32):
        origin = vec2(x0, z0)
        if ti.static(atomic):
            for p in range(n):
                p2g_one(p, 0, origin, inv_dx, dt, p_vol, p_mass, tool_on, n_plates)
        else:
            for lane in range(lanes):
                for p in range(lane * n // lanes, (lane + 1) * n // lanes):
                    p2g_one(p, lane, origin, inv_dx, dt, p_vol, p_mass, tool_on, n_plates)

    # ------------------------------------------------------------ grid
    @ti.func
    def node_update(i: ti.i32, j: ti.i32, lane: ti.i32, nx: ti.i32, nz: ti.i32, x0: f32, z0: f32, dx: f32, dt: f32,
                    gravity: f32, damp: f32, sticky_floor: ti.i32, tool_on: ti.i32, n_plates: ti.i32, tip, vtip,
                    omega: f32, c0: f32, s0: f32, band: f32, tan_delta: f32, adhesion_impulse: f32):
        m = 0.0
        mom = vec2(0.0, 0.0)
        for ln in ti.static(range(lanes)):
            m += lane_m[ln, i, j]
            mom += lane_v[ln, i, j]
            lane_m[ln, i, j] = 0.0
            lane_v[ln, i, j] = vec2(0.0, 0.0)
        vel = vec2(0.0, 0.0)
        if m > 0.0:
            vel = mom / m
            vel[1] -= dt * gravity
            vel *= damp
            node = vec2(x0 + i * dx, z0 + j * dx)
            if tool_on and in_box(node, 0, band + 0.01 * dx):
                rel = node - tip
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
                        add_to(impulse, lane, ti.cast(m, ti.f64) * ti.cast(dv, ti.f64))
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
    def grid_update(nx: ti.i32, nz: ti.i32, x0: f32, z0: f32, dx: f32, dt: f32, gravity: f32, damp: f32,
                    sticky_floor: ti.i32, tool_on: ti.i32, n_plates: ti.i32,
                    tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32,
                    band: f32, tan_delta: f32, adhesion_impulse: f32):
        c0, s0 = ti.cos(a0), ti.sin(a0)
        tip = vec2(tx0, tz0)
        vtip = vec2(tx1 - tx0, tz1 - tz0) / dt
        omega = (a1 - a0) / dt
        if ti.static(atomic):
            for i, j in ti.ndrange(nx, nz):
                node_update(i, j, 0, nx, nz, x0, z0, dx, dt, gravity, damp, sticky_floor, tool_on, n_plates, tip,
                            vtip, omega, c0, s0, band, tan_delta, adhesion_impulse)
        else:
            for lane in range(lanes):
                for i in range(lane * nx // lanes, (lane + 1) * nx // lanes):
                    for j in range(nz):
                        node_update(i, j, lane, nx, nz, x0, z0, dx, dt, gravity, damp, sticky_floor, tool_on,
                                    n_plates, tip, vtip, omega, c0, s0, band, tan_delta, adhesion_impulse)

    # ------------------------------------------------------------ grid -> particle
    @ti.func
    def g2p_one(p: ti.i32, lane: ti.i32, origin, inv_dx: f32, dt: f32, p_mass: f32, mu: f32, lam: f32,
                sin_phi: f32, cos_phi: f32, cohesion: f32, tool_on: ti.i32, n_plates: ti.i32, tip0, tip1, vtip,
                omega: f32, c0: f32, s0: f32, c1: f32, s1: f32, guard: f32, x_lo: f32, x_hi: f32, z_lo: f32,
                z_hi: f32):
        dx = 1.0 / inv_dx
        near = near_flag[p]
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
        # elastic predictor and Mohr-Coulomb return mapping in log-strain space; the principal stretches
        # and directions from the eigen-decomposition of b = F F^T (the U and sigma^2 of F's SVD)
        f_new = (ti.Matrix.identity(f32, 2) + dt * new_c) @ F[p]
        b = f_new @ f_new.transpose()
        h = 0.5 * (b[0, 0] - b[1, 1])
        disc = ti.sqrt(h * h + b[0, 1] * b[0, 1])
        mid = 0.5 * (b[0, 0] + b[1, 1])
        l0 = mid + disc
        l1 = mid - disc
        c, s = 1.0, 0.0
        if disc > 1e-7 * mid:
            ux, uz = b[0, 1], l0 - b[0, 0]
            if h > 0.0:
                ux, uz = l0 - b[1, 1], b[0, 1]
            inv = 1.0 / ti.sqrt(ux * ux + uz * uz)
            c, s = ux * inv, uz * inv
        U = mat2([[c, -s], [s, c]])
        e0 = 0.5 * ti.log(ti.max(l0, 1e-8))
        e1 = 0.5 * ti.log(ti.max(l1, 1e-8))
        r0, r1 = e0, e1
        e0, e1, plastic = return_mapping(e0, e1, mu, lam, sin_phi, cos_phi, cohesion)
        if ti.static(svd_f):
            # the old kernels' update: the return mapping on the SVD's log stretches, F rebuilt from them
            Us, sig, Vs = ti.svd(f_new)
            g0, g1, _ = return_mapping(ti.log(ti.max(sig[0, 0], 1e-4)), ti.log(ti.max(sig[1, 1], 1e-4)), mu, lam,
                                       sin_phi, cos_phi, cohesion)
            F[p] = Us @ mat2([[ti.exp(g0), 0.0], [0.0, ti.exp(g1)]]) @ Vs.transpose()
        elif plastic:
            # F = U diag(exp(e)) V^T with V^T = diag(exp(-r)) U^T f_new (r: the predictor's log stretches)
            F[p] = U @ mat2([[ti.exp(e0 - r0), 0.0], [0.0, ti.exp(e1 - r1)]]) @ U.transpose() @ f_new
        else:
            F[p] = f_new
        tau[p] = kirchhoff(U, e0, e1, mu, lam)
        C[p] = new_c
        x_old = x[p]
        x_new = x_old + dt * new_v
        if tool_on:
            if in_box(x_old, 0, TRANSFER_REACH * dx) or in_box(x_new, 1, TRANSFER_REACH * dx):
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
                                add_to(guard_impulse, lane, ti.cast(p_mass * rn * nrm, ti.f64))
                            add_to(guarded, lane, 1)
        x_new[0] = ti.min(ti.max(x_new[0], x_lo), x_hi)
        x_new[1] = ti.min(ti.max(x_new[1], z_lo), z_hi)
        v[p] = new_v
        x[p] = x_new

    @ti.func
    def g2p(n: ti.i32, x0: f32, z0: f32, inv_dx: f32, dt: f32, p_mass: f32, mu: f32, lam: f32, sin_phi: f32,
            cos_phi: f32, cohesion: f32, tool_on: ti.i32, n_plates: ti.i32,
            tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32, guard: f32,
            x_lo: f32, x_hi: f32, z_lo: f32, z_hi: f32):
        origin = vec2(x0, z0)
        c0, s0 = ti.cos(a0), ti.sin(a0)
        c1, s1 = ti.cos(a1), ti.sin(a1)
        tip0 = vec2(tx0, tz0)
        tip1 = vec2(tx1, tz1)
        vtip = (tip1 - tip0) / dt
        omega = (a1 - a0) / dt
        if ti.static(atomic):
            for p in range(n):
                g2p_one(p, 0, origin, inv_dx, dt, p_mass, mu, lam, sin_phi, cos_phi, cohesion, tool_on, n_plates,
                        tip0, tip1, vtip, omega, c0, s0, c1, s1, guard, x_lo, x_hi, z_lo, z_hi)
        else:
            for lane in range(lanes):
                for p in range(lane * n // lanes, (lane + 1) * n // lanes):
                    g2p_one(p, lane, origin, inv_dx, dt, p_mass, mu, lam, sin_phi, cos_phi, cohesion, tool_on,
                            n_plates, tip0, tip1, vtip, omega, c0, s0, c1, s1, guard, x_lo, x_hi, z_lo, z_hi)

    # ------------------------------------------------------------ kernels
    @ti.func
    def place_tool(n_plates: ti.i32, tx0: f32, tz0: f32, a0: f32, tx1: f32, tz1: f32, a1: f32):
        """World plates at the step's start pose; the plates' boxes at its start (0) and end (1) pose."""
        for _ in range(1):  # one serial task
            c0, s0 = ti.cos(a0), ti.sin(a0)
            c1, s1 = ti.cos(a1), ti.sin(a1)
            b0 = ti.Vector([1e30, 1e30, -1e30, -1e30], f32)
            b1 = ti.Vector([1e30, 1e30, -1e30, -1e30], f32)
            for k in range(n_plates):
                world_a[k] = vec2(tx0, tz0) + body_to_world(plate_a[k], c0, s0)
                world_b[k] = vec2(tx0, tz0) + body_to_world(plate_b[k], c0, s0)
                e_a = vec2(tx1, tz1) + body_to_world(plate_a[k], c1, s1)
                e_b = vec2(tx1, tz1) + body_to_world(plate_b[k], c1, s1)
                for q in ti.static(range(2)):
                    b0[q] = ti.min(b0[q], ti.min(world_a[k][q], world_b[k][q]))
                    b0[q + 2] = ti.max(b0[q + 2], ti.max(world_a[k][q], world_b[k][q]))
                    b1[q] = ti.min(b1[q], ti.min(e_a[q], e_b[q]))
                    b1[q + 2] = ti.max(b1[q + 2], ti.max(e_a[q], e_b[q]))
            box[0] = b0
            box[1] = b1

    @ti.kernel
    def reset_counters():
        for k in range(lanes):
            impulse[k] = ti.Vector([0.0, 0.0], ti.f64)
            guard_impulse[k] = ti.Vector([0.0, 0.0], ti.f64)
            guarded[k] = 0

    @ti.kernel
    def init_stress(n: ti.i32, mu: f32, lam: f32):
        for p in range(n):
            U, sig, _V = ti.svd(F[p])
            tau[p] = kirchhoff(U, ti.log(ti.max(sig[0, 0], 1e-4)), ti.log(ti.max(sig[1, 1], 1e-4)), mu, lam)

    @ti.kernel
    def substep(k: ti.i32):
        """Step ``k`` of the poses in ``pose`` with the settings in ``iparam`` and ``fparam`` (:data:`INT_PARAMS`,
        :data:`FLOAT_PARAMS`)."""
        n, nx, nz = iparam[0], iparam[1], iparam[2]
        sticky_floor, tool_on, n_plates = iparam[3], iparam[4], iparam[5]
        x0, z0, dx, dt, p_vol, p_mass = fparam[0], fparam[1], fparam[2], fparam[3], fparam[4], fparam[5]
        mu, lam, sin_phi, cos_phi, cohesion = fparam[6], fparam[7], fparam[8], fparam[9], fparam[10]
        gravity, damp, band, tan_delta, adhesion_impulse = fparam[11], fparam[12], fparam[13], fparam[14], fparam[15]
        guard, x_lo, x_hi, z_lo, z_hi = fparam[16], fparam[17], fparam[18], fparam[19], fparam[20]
        tx0, tz0, a0 = pose[k, 0], pose[k, 1], pose[k, 2]
        tx1, tz1, a1 = pose[k + 1, 0], pose[k + 1, 1], pose[k + 1, 2]
        inv_dx = 1.0 / dx
        place_tool(n_plates, tx0, tz0, a0, tx1, tz1, a1)
        p2g(n, x0, z0, inv_dx, dt, p_vol, p_mass, tool_on, n_plates)
        grid_update(nx, nz, x0, z0, dx, dt, gravity, damp, sticky_floor, tool_on, n_plates, tx0, tz0, a0, tx1, tz1,
                    a1, band, tan_delta, adhesion_impulse)
        g2p(n, x0, z0, inv_dx, dt, p_mass, mu, lam, sin_phi, cos_phi, cohesion, tool_on, n_plates, tx0, tz0, a0,
            tx1, tz1, a1, guard, x_lo, x_hi, z_lo, z_hi)

    return substep, reset_counters, init_stress
