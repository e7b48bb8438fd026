"""Quasi-2D DEM bucket-filling scenario for Yade (ground truth for the FEE estimator).

Run under Yade on the system Python (it may import only yade, numpy and the
standard library)::

    yade -n -j1 -x dem/yade_scenario.py --out DIR --path cycle1.csv [--path cycle2.csv ...] [options]

Normally it is driven by ``wheelloader dem`` / :mod:`wheelloader.references.dem`, which
writes the path CSVs, runs Yade as a subprocess and converts the raw output
into ``CycleLog`` files. ``--help`` lists every option.

Scene
-----
* A slab ``--slab-width`` wide in y between two frictionless walls (plane
  strain). x is the digging direction, z up, the pile toe at ``--toe-x``.
* A soil bed ``--bed`` deep (z from -bed to 0) on a rigid floor, reaching
  ``--front`` in front of the toe, and on it a trapezoidal pile: front slope
  ``--slope-deg``, height ``--pile-height``, flat top ``--top-length`` long,
  ending at a frictionless back wall (the back half of the pile is not
  simulated).
* Spheres of mean radius ``--radius`` (uniform spread +-``--radius-spread``),
  Hertz-Mindlin contacts with rolling resistance (and DMT adhesion for a
  cohesive soil); material per ``--soil`` (table ``SOILS`` below). The
  particle density is set after the first settling so that the measured bulk
  density of the pile equals the soil's target bulk density.
* A rigid bucket of facets (floor ending in the cutting edge, back plate, top
  plate; the slab walls act as its side plates), driven kinematically along
  each path CSV (columns t, x, z, blade_angle: the tip position and the
  angle of the floor from its back edge to the tip above +x).

Settling (deposit on a jittered lattice with low friction, carve the
trapezoid, switch to the soil's friction, settle again) is cached in
``--cache-dir`` under a key of every parameter that shapes the pile.

Output in ``--out``
-------------------
``cycle<i>.csv`` per path: 60 Hz (the path's own sample times, then the
hold) columns ``t, x, z, blade_angle`` (measured tip pose), ``Fx, Fy, Fz``
(total soil force on the bucket [N], window-averaged over each sample
interval, centred), ``F_T, F_N`` (blade frame, see below), ``mass_inside``
(kg of particles whose centre lies inside the bucket outline), ``contacts``
(real contacts on the bucket), ``phase`` (0 path, 1 hold).
``summary.json``: parameters, particle count, densities, pile surfaces
before/after each cycle, carried masses, timings.

Blade frame: ``e = (cos a, sin a)`` points along the floor from its back edge
to the tip (a = blade angle); ``F_T = -F . e`` (positive resisting
penetration, eq 16) and ``F_N = F . (sin a, -cos a)`` (positive pressing the
floor away from the soil above it, i.e. away from the soil wedge, eq 17).
"""

import argparse
import hashlib
import json
import math
import os
import sys
import time

import numpy as np
from yade import O, Quaternion, Vector3, utils
from yade.wrapper import (
    Bo1_Facet_Aabb,
    Bo1_Sphere_Aabb,
    Bo1_Wall_Aabb,
    ForceResetter,
    FrictMat,
    Ig2_Facet_Sphere_ScGeom,
    Ig2_Sphere_Sphere_ScGeom,
    Ig2_Wall_Sphere_ScGeom,
    InsertionSortCollider,
    InteractionLoop,
    Ip2_FrictMat_FrictMat_MindlinPhys,
    Law2_ScGeom_MindlinPhys_Mindlin,
    NewtonIntegrator,
    Sphere,
)

#: Bump when the settling procedure changes (invalidates cached piles).
SCENARIO_VERSION = 1
GRAVITY = 9.81

#: Counterparts of the paper's Table 2 soils. ``friction``: inter-particle
#: friction angle [rad] (= Table 2 bulk friction angle; not calibrated to
#: reproduce it), ``rolling``: rolling-resistance coefficient eta (= Table 2
#: particle rolling resistance; plastic bending moment eta * R_mean * F_n),
#: ``bulk_density``: target bulk density of the settled pile [kg/m^3],
#: ``cohesion``: target cohesion C [Pa], realised as DMT adhesion with
#: surface energy 2 C r / pi (adhesion force 4 pi R* gamma = C (2r)^2 for two
#: equal spheres), ``bucket_friction``: soil-steel contact friction angle
#: [rad] (2/3 of the particle friction, a common choice; Table 2 has none).
SOILS = {
    "gravel": {"friction": 0.7679, "rolling": 0.3, "bulk_density": 1474.0, "cohesion": 0.0},
    "sand": {"friction": 0.6807, "rolling": 0.1, "bulk_density": 1474.0, "cohesion": 0.0},
    "dirt": {"friction": 0.6978, "rolling": 0.1, "bulk_density": 1474.0, "cohesion": 2100.0},
    "modified_sand": {"friction": 0.5934, "rolling": 0.1, "bulk_density": 1874.5, "cohesion": 0.0},
}
for _soil in SOILS.values():
    _soil["bucket_friction"] = round(2.0 / 3.0 * _soil["friction"], 4)

#: Friction angle during the first (deposition) settling [rad]: low for a dense packing.
DEPOSIT_FRICTION = 0.2
#: Solid fraction assumed before the density is corrected.
ASSUMED_SOLID_FRACTION = 0.6


def log(msg):
    print(f"[dem] {msg}", flush=True)


# --------------------------------------------------------------------------- arguments
def parse_args(argv):
    p = argparse.ArgumentParser(prog="yade_scenario.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="output directory (created)")
    p.add_argument("--path", action="append", default=[], help="path CSV (t,x,z,blade_angle); repeat for cycles")
    p.add_argument("--cache-dir", default=os.path.expanduser("~/.cache/wheelloader/dem"),
                   help="settled-pile cache directory")
    p.add_argument("--settle-only", action="store_true", help="settle (or load) the pile and stop")
    g = p.add_argument_group("soil")
    g.add_argument("--soil", default="gravel", choices=sorted(SOILS))
    g.add_argument("--bulk-density", type=float, default=None,
                   help="override the soil's target bulk density [kg/m^3]")
    g.add_argument("--radius", type=float, default=0.03, help="mean particle radius [m]")
    g.add_argument("--radius-spread", type=float, default=0.15, help="relative half-width of the radius range")
    g.add_argument("--young", type=float, default=5e7, help="Young's modulus of particles and bucket [Pa]")
    g.add_argument("--poisson", type=float, default=0.3)
    g.add_argument("--restitution", type=float, default=0.3, help="normal and shear restitution coefficient")
    g.add_argument("--seed", type=int, default=1)
    g = p.add_argument_group("pile")
    g.add_argument("--slab-width", type=float, default=0.35, help="slab width in y [m]")
    g.add_argument("--pile-height", type=float, default=0.6, help="[m]")
    g.add_argument("--slope-deg", type=float, default=30.0, help="front slope [deg]")
    g.add_argument("--top-length", type=float, default=0.4, help="flat top up to the back wall [m]")
    g.add_argument("--toe-x", type=float, default=0.0, help="x of the pile toe [m]")
    g.add_argument("--bed", type=float, default=0.2, help="soil bed depth below z=0 [m]")
    g.add_argument("--front", type=float, default=0.15, help="bed length in front of the toe [m]")
    g.add_argument("--surface", default=None,
                   help="CSV (columns x,z) of the surface to carve the deposit to, instead of the trapezoid "
                        "(e.g. a pile carved by earlier cycles); needs --x-back")
    g.add_argument("--x-back", type=float, default=None,
                   help="x of the back wall [m] (default: the trapezoid's, toe + height / tan(slope) + top length)")
    g = p.add_argument_group("bucket")
    g.add_argument("--floor-length", type=float, default=0.27, help="floor, back edge to tip [m]")
    g.add_argument("--back-height", type=float, default=0.27, help="back plate, normal to the floor [m]")
    g.add_argument("--top-plate", type=float, default=0.09, help="top plate from the back plate toward the tip [m]")
    g.add_argument("--side-gap", type=float, default=0.004, help="gap between bucket and slab walls [m]")
    g = p.add_argument_group("run")
    g.add_argument("--hold", type=float, default=0.4, help="hold at the end pose after each path [s]")
    g.add_argument("--between", type=float, default=0.3, help="settling between cycles (after dumping) [s]")
    g.add_argument("--settle-after", type=float, default=0.0,
                   help="after the last cycle: take the load and the bucket away, let the pile settle this long [s] "
                        "and report that surface as the last cycle's pile_after (default 0: measured with the "
                        "bucket in place, its load excluded)")
    g.add_argument("--damping", type=float, default=0.0, help="Newton (local) damping during cycles")
    g.add_argument("--dt-factor", type=float, default=1.0, help="time step / PWaveTimeStep")
    g.add_argument("--max-settle", type=float, default=4.0, help="longest settling phase [s]")
    a = p.parse_args(argv)
    material = dict(SOILS[a.soil])
    if a.bulk_density is not None:
        if not a.bulk_density > 0:
            raise SystemExit(f"--bulk-density must be > 0, got {a.bulk_density}")
        material["bulk_density"] = a.bulk_density
    a.material = material
    a.surface_x = a.surface_z = None
    if a.surface is not None:
        if a.x_back is None:
            raise SystemExit("--surface needs --x-back (where the simulated pile ends)")
        data = np.genfromtxt(a.surface, delimiter=",", names=True)
        a.surface_x, a.surface_z = np.asarray(data["x"], float), np.asarray(data["z"], float)
        if a.surface_x.size < 2 or np.any(np.diff(a.surface_x) <= 0) or not np.all(np.isfinite(a.surface_z)):
            raise SystemExit(f"--surface {a.surface}: x must increase and z be finite (at least 2 points)")
        if np.any(a.surface_z < -a.bed):
            raise SystemExit(f"--surface {a.surface}: z below the floor (-{a.bed} m)")
    if a.x_back is not None and not a.x_back > a.toe_x - a.front:
        raise SystemExit(f"--x-back {a.x_back} must lie behind the front of the bed ({a.toe_x - a.front} m)")
    return a


# --------------------------------------------------------------------------- geometry
def pile_profile(x, a):
    """Target surface of the pile z_s(x) [m] (bed surface 0 in front of the toe; ``--surface`` if given)."""
    if a.surface_x is not None:
        return np.interp(np.asarray(x, dtype=float), a.surface_x, a.surface_z)
    tan = math.tan(math.radians(a.slope_deg))
    return np.clip((np.asarray(x, dtype=float) - a.toe_x) * tan, 0.0, a.pile_height)


def domain(a):
    x_front = a.toe_x - a.front
    if a.x_back is not None:
        return x_front, a.x_back
    x_back = a.toe_x + a.pile_height / math.tan(math.radians(a.slope_deg)) + a.top_length
    return x_front, x_back


def settle_key(a):
    keys = ["soil", "bulk_density", "radius", "radius_spread", "young", "poisson", "restitution", "seed", "slab_width",
            "pile_height", "slope_deg", "top_length", "toe_x", "bed", "front", "dt_factor", "max_settle"]
    data = {k: getattr(a, k) for k in keys}
    if a.x_back is not None or a.surface_x is not None:  # (absent from the keys of the trapezoid's cached piles)
        data["x_back"] = a.x_back
        data["surface"] = None if a.surface_x is None else hashlib.sha256(
            np.ascontiguousarray(np.concatenate([a.surface_x, a.surface_z])).tobytes()).hexdigest()
    data["material"] = a.material
    data["version"] = SCENARIO_VERSION
    data["yade"] = yade_version()
    text = json.dumps(data, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16], data


def yade_version():
    try:
        import yade.config
        return str(yade.config.version)
    except Exception:  # pragma: no cover - very old Yade
        return "unknown"


# --------------------------------------------------------------------------- materials and engines
def make_materials(a, friction):
    soil = a.material
    rho_p = soil["bulk_density"] / ASSUMED_SOLID_FRACTION
    mats = {
        "soil": FrictMat(young=a.young, poisson=a.poisson, frictionAngle=friction, density=rho_p, label="mat_soil"),
        "wall": FrictMat(young=a.young, poisson=a.poisson, frictionAngle=0.0, density=1000.0, label="mat_wall"),
        "steel": FrictMat(young=a.young, poisson=a.poisson, frictionAngle=soil["bucket_friction"], density=7800.0,
                          label="mat_steel"),
    }
    for m in mats.values():
        O.materials.append(m)
    return mats


def engines(a, damping, run_physics):
    """Engine list; ``run_physics`` switches rolling resistance and adhesion on."""
    soil = a.material
    if run_physics:
        eta = soil["rolling"]
        krot = 0.05 * a.young * a.radius ** 3
        gamma = 2.0 * soil["cohesion"] * a.radius / math.pi
    else:
        eta = krot = gamma = 0.0
    ip2 = Ip2_FrictMat_FrictMat_MindlinPhys(en=a.restitution, es=a.restitution, eta=eta, krot=krot, ktwist=0.0,
                                            gamma=gamma)
    law = Law2_ScGeom_MindlinPhys_Mindlin(includeMoment=eta > 0.0, includeAdhesion=gamma > 0.0)
    return [
        ForceResetter(),
        InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb(), Bo1_Wall_Aabb()]),
        InteractionLoop([Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom(), Ig2_Wall_Sphere_ScGeom()], [ip2],
                        [law]),
        NewtonIntegrator(damping=damping, gravity=(0, 0, -GRAVITY)),
    ]


def sphere_ids():
    return [b.id for b in O.bodies if b is not None and isinstance(b.shape, Sphere)]


def sphere_arrays(ids):
    pos = np.empty((len(ids), 3))
    rad = np.empty(len(ids))
    mass = np.empty(len(ids))
    for k, i in enumerate(ids):
        b = O.bodies[i]
        p = b.state.pos
        pos[k] = (p[0], p[1], p[2])
        rad[k] = b.shape.radius
        mass[k] = b.state.mass
    return pos, rad, mass


def surface_grid(a):
    x_front, x_back = domain(a)
    x0 = x_front - 0.4
    n = int(round((x_back - x0) / 0.01)) + 1
    return x0 + 0.01 * np.arange(n)


def measure_surface(a, ids, exclude=None):
    """Upper envelope of the particle silhouettes in the x-z plane on a 1 cm grid (floor where empty)."""
    xs = surface_grid(a)
    z = np.full(xs.size, -a.bed)
    if ids:
        pos, rad, _ = sphere_arrays(ids)
        keep = np.ones(len(ids), bool) if exclude is None else ~exclude
        pos, rad = pos[keep], rad[keep]
        dx = xs[None, :] - pos[:, 0:1]
        inside = np.abs(dx) < rad[:, None]
        top = np.where(inside, pos[:, 2:3] + np.sqrt(np.clip(rad[:, None] ** 2 - dx ** 2, 0.0, None)), -np.inf)
        z = np.maximum(z, top.max(axis=0))
    return xs, z


def surface_area(a, xs, z):
    h = z + a.bed
    return float(np.sum(0.5 * (h[1:] + h[:-1]) * np.diff(xs)))


def unbalanced():
    try:
        return utils.unbalancedForce()
    except Exception:
        return 1.0


def settle(min_time, tol, max_time, what):
    t0 = O.time
    t_wall = time.time()
    chunk = max(1, int(0.05 / O.dt))
    rounds = 0
    while True:
        O.run(chunk, True)
        rounds += 1
        elapsed = O.time - t0
        ub = unbalanced()
        if elapsed >= min_time and ub < tol:
            break
        if elapsed >= max_time:
            log(f"{what}: stopped at max time {max_time:g} s (unbalanced force {ub:.3g})")
            break
        if rounds % 5 == 0:
            log(f"{what}: t={elapsed:.2f} s unbalanced={ub:.3g} wall={time.time() - t_wall:.1f} s")
    log(f"{what}: settled in {O.time - t0:.2f} s simulated, {time.time() - t_wall:.1f} s wall, "
        f"unbalanced force {unbalanced():.3g}")


# --------------------------------------------------------------------------- settling
def build_pile(a):
    """Deposit, carve and settle the pile; return info for the summary."""
    O.reset()
    rng = np.random.default_rng(a.seed)
    mats = make_materials(a, DEPOSIT_FRICTION)
    x_front, x_back = domain(a)
    r_max = a.radius * (1.0 + a.radius_spread)
    r_min = a.radius * (1.0 - a.radius_spread)
    if a.slab_width < 4.0 * r_max:
        raise SystemExit(f"--slab-width {a.slab_width} must be at least 4 particle radii ({4 * r_max:.3f} m)")
    cell = 2.0 * r_max * 1.02
    # walls: floor, side walls, back wall, temporary front wall
    O.bodies.append(utils.wall((0, 0, -a.bed), axis=2, sense=1, material=mats["soil"]))
    O.bodies.append(utils.wall((0, 0, 0), axis=1, sense=1, material=mats["wall"]))
    O.bodies.append(utils.wall((0, a.slab_width, 0), axis=1, sense=-1, material=mats["wall"]))
    O.bodies.append(utils.wall((x_back, 0, 0), axis=0, sense=-1, material=mats["wall"]))
    front_wall = O.bodies.append(utils.wall((x_front, 0, 0), axis=0, sense=1, material=mats["wall"]))
    # jittered simple-cubic lattice; it collapses into a random dense packing
    nx = int((x_back - x_front) / cell)
    ny = int(a.slab_width / cell)
    lattice_fraction = 4.0 / 3.0 * math.pi * a.radius ** 3 * (1 + a.radius_spread ** 2) / cell ** 3
    top = float(np.max(pile_profile(np.linspace(x_front, x_back, 401), a)))  # the trapezoid's: pile_height
    needed = top + a.bed + 2 * r_max
    nz = int(math.ceil(needed * ASSUMED_SOLID_FRACTION / lattice_fraction / cell * 1.08))
    ox = x_front + 0.5 * ((x_back - x_front) - nx * cell)
    oy = 0.5 * (a.slab_width - ny * cell)
    count = 0
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                r = float(rng.uniform(r_min, r_max))
                slack = 0.5 * cell - r
                c = (ox + (i + 0.5) * cell + rng.uniform(-slack, slack),
                     oy + (j + 0.5) * cell + rng.uniform(-slack, slack),
                     -a.bed + (k + 0.5) * cell + rng.uniform(-slack, slack))
                O.bodies.append(utils.sphere(c, r, material=mats["soil"]))
                count += 1
    O.engines = engines(a, damping=0.4, run_physics=False)
    O.dt = a.dt_factor * utils.PWaveTimeStep()
    log(f"deposit: {count} spheres on a {nx}x{ny}x{nz} lattice, dt={O.dt:.3g} s")
    settle(0.6, 0.02, a.max_settle, "deposit")
    # carve the trapezoid: drop spheres whose centre is above the target surface minus half a radius
    removed = 0
    for i in sphere_ids():
        b = O.bodies[i]
        p = b.state.pos
        if p[2] > float(pile_profile(p[0], a)) - 0.5 * b.shape.radius:
            O.bodies.erase(i)
            removed += 1
    O.bodies.erase(front_wall)
    ids = sphere_ids()
    log(f"carve: removed {removed}, kept {len(ids)} spheres")
    # set the particle density so that the bulk density (mass / volume under the measured surface) is the target
    xs, z = measure_surface(a, ids)
    area = surface_area(a, xs, z)
    _, rad, _ = sphere_arrays(ids)
    solid = float(np.sum(4.0 / 3.0 * math.pi * rad ** 3))
    fraction = solid / (area * a.slab_width)
    rho_p = a.material["bulk_density"] / fraction
    mats["soil"].density = rho_p
    for i in ids:
        b = O.bodies[i]
        r = b.shape.radius
        m = rho_p * 4.0 / 3.0 * math.pi * r ** 3
        b.state.mass = m
        b.state.inertia = Vector3(1, 1, 1) * (0.4 * m * r * r)
    # material friction, rolling resistance and adhesion; new contacts pick them up
    mats["soil"].frictionAngle = a.material["friction"]
    O.interactions.clear()
    O.engines = engines(a, damping=0.2, run_physics=True)
    settle(0.6, 0.01, a.max_settle, "settle")
    # a short undamped phase so that the saved state is at rest under the run settings
    O.engines = engines(a, damping=a.damping, run_physics=True)
    O.run(int(0.1 / O.dt), True)
    return {"deposited": count, "solid_fraction_at_density_fit": fraction, "particle_density": rho_p}


def load_or_build(a):
    key, data = settle_key(a)
    os.makedirs(a.cache_dir, exist_ok=True)
    stem = os.path.join(a.cache_dir, f"pile-{a.soil}-{key}")
    state, info_path = stem + ".yade.gz", stem + ".json"
    t0 = time.time()
    if os.path.exists(state) and os.path.exists(info_path):
        log(f"loading cached pile {state}")
        with open(info_path) as fh:
            info = json.load(fh)
        info["cached"] = True
    else:
        log(f"settling a new pile (cache key {key})")
        info = build_pile(a)
        info["settle_wall_s"] = time.time() - t0
        info["key"] = data
        tmp = state + f".tmp{os.getpid()}.yade.gz"
        O.save(tmp)
        os.replace(tmp, state)
        with open(info_path + f".tmp{os.getpid()}", "w") as fh:
            json.dump(info, fh, indent=1)
        os.replace(info_path + f".tmp{os.getpid()}", info_path)
        info["cached"] = False
    O.load(state)  # always continue from the saved state: first and cached runs are identical
    info["cache_file"] = state
    return info


# --------------------------------------------------------------------------- bucket
class Bucket:
    """Rigid facet bucket; local frame (u along the floor toward the tip, w along its upper normal, y)."""

    def __init__(self, a, mat):
        self.L, self.H, self.Lt = a.floor_length, a.back_height, a.top_plate
        y0, y1 = a.side_gap, a.slab_width - a.side_gap
        self.y0, self.y1 = y0, y1
        # outline in the local frame: tip B, back edge A, back-plate top C, top-plate end D
        self.outline = np.array([[0.0, 0.0], [-self.L, 0.0], [-self.L, self.H], [-self.L + self.Lt, self.H]])
        self.plates = [(self.outline[0], self.outline[1]), (self.outline[1], self.outline[2]),
                       (self.outline[2], self.outline[3])]
        self.ids = []
        self.local = []
        for (u0, w0), (u1, w1) in self.plates:
            quad = [(u0, y0, w0), (u1, y0, w1), (u1, y1, w1), (u0, y1, w0)]
            for tri in ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3])):
                verts = [Vector3(u, y, w) for (u, y, w) in tri]  # built in the local frame = world at the origin
                f = utils.facet(verts, material=mat, wire=False)
                c = f.state.pos
                self.local.append((c[0], c[1], c[2]))
                self.ids.append(O.bodies.append(f))
        self.ori0 = [Quaternion(O.bodies[i].state.ori) for i in self.ids]
        self.theta = 0.0
        self.tip = (0.0, 0.0)

    @staticmethod
    def frame(theta):
        return (math.cos(theta), math.sin(theta)), (-math.sin(theta), math.cos(theta))

    def world(self, u, w, tip, theta):
        e, n = self.frame(theta)
        return tip[0] + u * e[0] + w * n[0], tip[1] + u * e[1] + w * n[1]

    def place(self, tip, theta):
        """Teleport to a pose (between cycles)."""
        for i, (u, y, w), q0 in zip(self.ids, self.local, self.ori0, strict=True):
            b = O.bodies[i]
            x, z = self.world(u, w, tip, theta)
            b.state.pos = Vector3(x, y, z)
            b.state.ori = Quaternion(Vector3(0, 1, 0), -theta) * q0
            b.state.vel = Vector3(0, 0, 0)
            b.state.angVel = Vector3(0, 0, 0)
        self.tip, self.theta = tip, theta

    def current(self):
        """Measured pose (tip x, tip z, blade angle) from the first facet's state."""
        b = O.bodies[self.ids[0]]
        q = b.state.ori * self.ori0[0].conjugate()
        v = q * Vector3(1, 0, 0)
        theta = math.atan2(v[2], v[0])
        u, _, w = self.local[0]
        e, n = self.frame(theta)
        p = b.state.pos
        return p[0] - u * e[0] - w * n[0], p[2] - u * e[1] - w * n[1], theta

    def steer(self, tip, theta, dt):
        """Set velocities so that every facet lands on the pose (tip, theta) after one step."""
        _, _, th_now = self.current()
        omega = Vector3(0, -(theta - th_now) / dt, 0)
        for i, (u, y, w) in zip(self.ids, self.local, strict=True):
            b = O.bodies[i]
            x, z = self.world(u, w, tip, theta)
            p = b.state.pos
            b.state.vel = Vector3((x - p[0]) / dt, (y - p[1]) / dt, (z - p[2]) / dt)
            b.state.angVel = omega

    def stop(self):
        for i in self.ids:
            O.bodies[i].state.vel = Vector3(0, 0, 0)
            O.bodies[i].state.angVel = Vector3(0, 0, 0)

    def to_local(self, pos, tip, theta):
        e, n = self.frame(theta)
        dx, dz = pos[:, 0] - tip[0], pos[:, 2] - tip[1]
        return dx * e[0] + dz * e[1], dx * n[0] + dz * n[1]

    def inside(self, pos, tip, theta):
        """Centres inside the bucket outline (floor, back, top plate and the strike line D-B)."""
        u, w = self.to_local(pos, tip, theta)
        strike = (-self.L + self.Lt) * w / self.H
        return (w >= 0.0) & (w <= self.H) & (u >= -self.L) & (u <= strike)

    def carried(self, pos, tip, theta):
        """Centres inside the outline or vertically above it (soil riding on the bucket)."""
        pts = [self.world(u, w, tip, theta) for u, w in self.outline]
        xs = np.array([p[0] for p in pts])
        zs = np.array([p[1] for p in pts])
        x, z = pos[:, 0], pos[:, 2]
        low = np.full(x.size, np.inf)
        for k in range(len(pts)):
            x0, z0, x1, z1 = xs[k], zs[k], xs[(k + 1) % len(pts)], zs[(k + 1) % len(pts)]
            if abs(x1 - x0) < 1e-12:
                continue
            lo, hi = min(x0, x1), max(x0, x1)
            on = (x >= lo) & (x <= hi)
            zl = z0 + (z1 - z0) * (x - x0) / (x1 - x0)
            low = np.where(on, np.minimum(low, zl), low)
        return np.isfinite(low) & (z >= low)

    def overlapping(self, pos, rad, tip, theta):
        """Spheres closer than their radius to a plate (for placing the bucket)."""
        u, w = self.to_local(pos, tip, theta)
        close = np.zeros(u.size, bool)
        for (u0, w0), (u1, w1) in self.plates:
            du, dw = u1 - u0, w1 - w0
            s = np.clip(((u - u0) * du + (w - w0) * dw) / (du * du + dw * dw), 0.0, 1.0)
            d = np.hypot(u - u0 - s * du, w - w0 - s * dw)
            close |= d < rad * 1.02
        return close

    def force(self):
        fx = fy = fz = 0.0
        for i in self.ids:
            f = O.forces.f(i)
            fx += f[0]
            fy += f[1]
            fz += f[2]
        return fx, fy, fz

    def contacts(self):
        n = 0
        for i in self.ids:
            n += sum(1 for it in O.bodies[i].intrs() if it.isReal)
        return n


def blade_components(fx, fz, theta):
    """(F_T, F_N): F_T = -F . e, F_N = F . (sin a, -cos a) (see module docstring)."""
    c, s = math.cos(theta), math.sin(theta)
    return -(fx * c + fz * s), fx * s - fz * c


# --------------------------------------------------------------------------- cycles
def read_path(fname):
    with open(fname) as fh:
        lines = [ln for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    header = [h.strip() for h in lines[0].split(",")]
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    cols = {h: data[:, k] for k, h in enumerate(header)}
    for need in ("t", "x", "z", "blade_angle"):
        if need not in cols:
            raise SystemExit(f"{fname}: missing column {need!r}")
    t = cols["t"] - cols["t"][0]
    if np.any(np.diff(t) <= 0):
        raise SystemExit(f"{fname}: t must be strictly increasing")
    return t, cols["x"], cols["z"], cols["blade_angle"]


def remove_overlaps(bucket, tip, theta):
    ids = sphere_ids()
    pos, rad, mass = sphere_arrays(ids)
    bad = bucket.overlapping(pos, rad, tip, theta)
    for k in np.flatnonzero(bad):
        O.bodies.erase(ids[int(k)])
    return int(bad.sum()), float(mass[bad].sum())


def run_cycle(a, bucket, path, index, total):
    t_p, x_p, z_p, th_p = path
    dt = O.dt
    n_path = t_p.size
    rate_dt = float(np.median(np.diff(t_p)))
    n_hold = int(round(a.hold / rate_dt))
    times = np.concatenate([t_p, t_p[-1] + rate_dt * np.arange(1, n_hold + 1)])
    n = times.size
    acc = np.zeros((n, 3))
    cnt = np.zeros(n)
    pose = np.zeros((n, 3))
    mass_in = np.zeros(n)
    contacts = np.zeros(n)
    t0 = O.time
    t_end = times[-1] + 0.5 * rate_dt
    wall0 = time.time()
    next_sample = 0
    next_report = 0.5
    ids = sphere_ids()

    def target(t):
        if t >= t_p[-1]:
            return (x_p[-1], z_p[-1]), th_p[-1]
        k = int(np.searchsorted(t_p, t, side="right")) - 1
        k = max(0, min(k, n_path - 2))
        f = (t - t_p[k]) / (t_p[k + 1] - t_p[k])
        return (x_p[k] + f * (x_p[k + 1] - x_p[k]), z_p[k] + f * (z_p[k + 1] - z_p[k])), \
            th_p[k] + f * (th_p[k + 1] - th_p[k])

    while True:
        t = O.time - t0
        if t > t_end:
            break
        while next_sample < n and t >= times[next_sample] - 0.5 * dt:
            x, z, th = bucket.current()
            pose[next_sample] = (x, z, th)
            pos, _, mass = sphere_arrays(ids)
            mass_in[next_sample] = float(mass[bucket.inside(pos, (x, z), th)].sum())
            contacts[next_sample] = bucket.contacts()
            next_sample += 1
        if t + dt <= t_p[-1] + 1e-12 or t < t_p[-1]:
            tip, th = target(t + dt)
            bucket.steer(tip, th, dt)
        else:
            bucket.stop()
        O.step()
        k = int(round(t / rate_dt))
        if 0 <= k < n:
            f = bucket.force()
            acc[k] += f
            cnt[k] += 1
        if t >= next_report:
            log(f"cycle {index + 1}/{total}: t={t:.2f}/{times[-1]:.2f} s, wall {time.time() - wall0:.1f} s")
            next_report += 0.5
    cnt[cnt == 0] = 1
    force = acc / cnt[:, None]
    ft, fn = np.zeros(n), np.zeros(n)
    for k in range(n):
        ft[k], fn[k] = blade_components(force[k, 0], force[k, 2], pose[k, 2])
    phase = np.where(np.arange(n) < n_path, 0, 1)
    hold_tail = (phase == 1) & (times >= times[-1] - 0.5 * a.hold)
    load_mass = float(-force[hold_tail, 2].mean() / GRAVITY) if hold_tail.any() else float("nan")
    fname = os.path.join(a.out, f"cycle{index + 1}.csv")
    with open(fname, "w") as fh:
        fh.write("t,x,z,blade_angle,Fx,Fy,Fz,F_T,F_N,mass_inside,contacts,phase\n")
        for k in range(n):
            vals = [times[k], *pose[k], *force[k], ft[k], fn[k], mass_in[k], contacts[k], phase[k]]
            fh.write(",".join(repr(float(v)) for v in vals) + "\n")
    # soil carried at the end of the hold
    x, z, th = bucket.current()
    pos, _, mass = sphere_arrays(ids)
    carried = bucket.carried(pos, (x, z), th)
    info = {
        "csv": os.path.basename(fname),
        "samples": int(n_path),
        "hold_samples": int(n_hold),
        "wall_s": time.time() - wall0,
        "steps": int(round((O.time - t0) / dt)),
        "carried_mass_geometric": float(mass[carried].sum()),
        "carried_mass_load": load_mass,
        "mass_inside_end": float(mass_in[-1]),
        "max_tracking_error": float(np.max(np.hypot(pose[:n_path, 0] - x_p, pose[:n_path, 1] - z_p))),
    }
    return info, carried, ids


def main(argv):
    a = parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    wall0 = time.time()
    info = load_or_build(a)
    ids = sphere_ids()
    pos, rad, mass = sphere_arrays(ids)
    summary = {
        "format": "wheelloader.dem-raw",
        "scenario_version": SCENARIO_VERSION,
        "yade_version": yade_version(),
        "argv": argv,
        "params": {k: v for k, v in vars(a).items() if k not in ("surface_x", "surface_z")},
        "material": a.material,
        "settle": info,
        "particles": len(ids),
        "total_mass": float(mass.sum()),
        "dt": O.dt,
        "cycles": [],
    }
    if a.settle_only:
        xs, z = measure_surface(a, ids)
        summary["pile_surface"] = {"x": xs.tolist(), "z": z.tolist()}
        summary["bulk_density"] = float(mass.sum() / (surface_area(a, xs, z) * a.slab_width))
        with open(os.path.join(a.out, "summary.json"), "w") as fh:
            json.dump(summary, fh, indent=1)
        log(f"settle only: {len(ids)} spheres, bulk density {summary['bulk_density']:.1f} kg/m^3")
        return 0
    if not a.path:
        raise SystemExit("give at least one --path CSV (or --settle-only)")
    paths = [read_path(f) for f in a.path]
    O.engines = engines(a, damping=a.damping, run_physics=True)
    steel = [m for m in O.materials if m.label == "mat_steel"][0]
    bucket = Bucket(a, steel)
    for c, path in enumerate(paths):
        tip, th = (path[1][0], path[2][0]), path[3][0]
        bucket.place(tip, th)
        removed, removed_mass = remove_overlaps(bucket, tip, th)
        if c > 0 or removed:
            log(f"cycle {c + 1}: bucket placed, {removed} overlapping spheres removed ({removed_mass:.2f} kg)")
        if c > 0:
            O.run(max(1, int(a.between / O.dt)), True)
        ids = sphere_ids()
        pos, rad, mass = sphere_arrays(ids)
        xs, zb = measure_surface(a, ids)
        area_before = surface_area(a, xs, zb)
        bulk = float(mass.sum() / (area_before * a.slab_width))
        cinfo, carried, ids_run = run_cycle(a, bucket, path, c, len(paths))
        xs, za = measure_surface(a, ids_run, exclude=carried)
        _, _, mass_run = sphere_arrays(ids_run)
        area_after = surface_area(a, xs, za)
        removed_volume = (area_before - area_after) * a.slab_width
        cinfo.update({
            "path_csv": a.path[c],
            "particles": len(ids),
            "removed_at_placement": removed,
            "removed_mass_at_placement": removed_mass,
            "bulk_density": bulk,
            "pile_before": {"x": xs.tolist(), "z": zb.tolist()},
            "pile_after": {"x": xs.tolist(), "z": za.tolist()},
            "removed_volume": removed_volume,
            "removed_volume_mass": removed_volume * bulk,
            "pile_mass_before": float(mass.sum()),
            "pile_mass_after": float(mass_run[~carried].sum()),
        })
        last = c + 1 == len(paths)
        if not last or a.settle_after > 0.0:  # dump the bucket's contents
            for k in np.flatnonzero(carried):
                O.bodies.erase(ids_run[int(k)])
        if last and a.settle_after > 0.0:
            # the pile as the next cycle finds it: the load carried away, the bucket gone, the soil at rest
            for i in bucket.ids:
                O.bodies.erase(i)
            O.run(max(1, int(a.settle_after / O.dt)), True)
            xs, za = measure_surface(a, sphere_ids())
            cinfo["pile_after"] = {"x": xs.tolist(), "z": za.tolist()}
            cinfo["pile_after_settled_s"] = a.settle_after
        summary["cycles"].append(cinfo)
        log(f"cycle {c + 1}: {cinfo['wall_s']:.1f} s wall, carried {cinfo['carried_mass_geometric']:.2f} kg "
            f"(load {cinfo['carried_mass_load']:.2f} kg, carved volume x bulk density "
            f"{cinfo['removed_volume_mass']:.2f} kg)")
    summary["wall_s"] = time.time() - wall0
    with open(os.path.join(a.out, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    log(f"done in {summary['wall_s']:.1f} s")
    return 0


if __name__ == "__main__":
    rc = main(sys.argv[1:])
    sys.stdout.flush()
    os._exit(rc)
