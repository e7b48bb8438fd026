"""The MPM plant driven closed loop by a controller of the bucket-loading env: the env's sensors and kinematics on
the continuum (:meth:`MPMPlant.dig` with ``controller=``).

Every control step (the env's ``dt``, 1/60 s) the controller gets the observation the env would give
(:class:`~wheelloader.envs.BucketLoadingEnv`, its table of entries), built from the plant's state:

* tip pose and velocities: the commanded motion through the env's kinematics (rate limits, workspace), which the
  plant's kinematic bucket follows exactly;
* depth, rho, alpha: the tip against the pile the cycle started on (the env's geometry, the plant's start pile);
* fill: the plant's soil inside the bucket outline over the bucket's capacity;
* F_T, F_N: the plant's mean force on the bucket over the last control step, in the blade frame, in kN, clipped
  to the env's sensor range; no sensor noise. Before the first step (the bucket at rest out of the soil) zero;
* the surface ahead: the plant's resting soil (the soil inside the bucket excluded) at ``x + lookahead`` minus the
  tip's height, the start pile outside the simulated range.

The cycle ends by the env's rules (:mod:`wheelloader.envs.bookkeeping`): out of the soil after loading, a stall
(the plant's F_T or F_N above the loader's limits for ``stall_patience`` steps; the bucket being kinematic, the step
is not undone, the cycle ends there with the bucket where it is), or the env's step limit
(:data:`~wheelloader.envs.config.STEPS_PER_CYCLE`). Where the bucket may go is fixed before the cycle (the
solver's domain): the poses of the path given (e.g. the policy's own path in the FEE env) widened by
:data:`ENVELOPE_AHEAD` along x and :data:`ENVELOPE_ABOVE` up, within the env's workspace; a commanded pose beyond it
is held at its edge (the velocity follows, as at the workspace's edges in the env) and the step counted where the
envelope, not the env's own workspace (e.g. the ground), held it (``metadata["closed_loop"]["envelope_steps"]``).

The log is the plant's as for a path (:meth:`MPMPlant.finish`): the forces are the means over each sample's interval
centred on the sample, the path the poses the controller commanded. What the cycle did is in
``metadata["closed_loop"]``: how it ended (``"exit"``, ``"stall"``, ``"step limit"``), its steps, the steps above
the loader's limits and those held at the envelope.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wheelloader.envs.bookkeeping import cycle_done, cycle_progress
from wheelloader.envs.config import STEPS_PER_CYCLE, EnvConfig
from wheelloader.estimator import BucketPath, CycleLog, Pile, SoilParams
from wheelloader.estimator.kinematics import surface_contact

from ..metrics import blade_frame
from .scene import surface_columns
from .tool import Trajectory

#: How far beyond the given path's furthest tip x the bucket may go [m] (the domain grows with it: more soil).
ENVELOPE_AHEAD = 0.2
#: How far above the given path's highest tip z the bucket may go [m].
ENVELOPE_ABOVE = 0.3


def loop_env_config() -> EnvConfig:
    """The env settings of the adaptation loop's policies (:data:`wheelloader.adaptation.LOOP_ENV_KWARGS`), for a
    controller that does not say its own (an ``env_config`` attribute)."""
    from wheelloader.adaptation import LOOP_ENV_KWARGS

    return EnvConfig.from_kwargs("closed loop", **LOOP_ENV_KWARGS)


def envelope(path: BucketPath, cfg: EnvConfig) -> tuple[tuple[float, float], tuple[float, float], Trajectory]:
    """The x and z ranges the bucket may take and the trajectory whose poses the domain must cover (the path's
    first pose first, at its first time, where the soil settles; then the envelope's corners at both blade-angle
    limits)."""
    (x0, x1), (z0, z1) = cfg.x_limits, cfg.z_limits
    xs = (max(x0, float(np.min(path.x)) - ENVELOPE_AHEAD), min(x1, float(np.max(path.x)) + ENVELOPE_AHEAD))
    zs = (z0, min(z1, float(np.max(path.z)) + ENVELOPE_ABOVE))
    corners = [(x, z, a) for x in xs for z in zs for a in cfg.blade_angle_limits]
    first = (float(path.x[0]), float(path.z[0]), float(path.blade_angle[0]))
    poses = np.array([first, *corners])
    t = float(path.t[0]) + np.arange(len(poses), dtype=float)
    return xs, zs, Trajectory(t, poses[:, 0], poses[:, 1], poses[:, 2])


class PlantSensors:
    """The env's observation of a cycle in the MPM plant, from the solver's state (see the module docstring)."""

    def __init__(self, cfg: EnvConfig, pile: Pile, run: Any, shape: Any, width: float) -> None:
        self.cfg, self.pile, self.shape, self.width = cfg, pile, shape, width
        scene = run.scene
        self.x_lo, self.x_hi = scene.soil_x
        self.spacing, self.z_bed = scene.spacing, scene.domain.z_min
        self.particle_volume = run.solver.particle_volume
        self.centres, self.before, _ = surface_columns(run.start_positions, self.x_lo, self.x_hi, self.spacing,
                                                       self.z_bed)
        self.lookahead = np.asarray(cfg.lookahead, dtype=float)

    def fill(self, pose: tuple[float, float, float], positions: np.ndarray) -> tuple[float, np.ndarray]:
        """The soil inside the bucket outline [m^3 per metre of width] and which particles it is."""
        inside = self.shape.inside(pose, positions)
        return float(np.count_nonzero(inside)) * self.particle_volume, inside

    def observation(self, pose: tuple, vel: tuple, fill_m: float, f_t: float, f_n: float, positions: np.ndarray,
                    inside: np.ndarray) -> np.ndarray:
        """The env's observation (its entry table), clipped to its limits."""
        cfg, pile = self.cfg, self.pile
        x, z, th = pose
        depth, rho, alpha, _, _ = surface_contact(pile, x, z, th, cfg.bucket.floor_length, cfg.slope_window)
        ahead = x + self.lookahead
        _, after, _ = surface_columns(positions, self.x_lo, self.x_hi, self.spacing, self.z_bed, exclude=inside)
        change = np.where((ahead >= self.x_lo) & (ahead <= self.x_hi),
                          np.interp(ahead, self.centres, after - self.before), 0.0)
        surface = pile.surface_height(ahead) + change - z
        r = cfg.sensor_range
        vals = [x, z, th, *vel, depth, rho, alpha, fill_m * self.width / cfg.bucket.capacity,
                min(max(f_t, -r), r) * 1e-3, min(max(f_n, -r), r) * 1e-3, *surface.tolist()]
        low, high = cfg.observation_limits
        return np.clip(np.array(vals, dtype=np.float32), low, high)


def env_step(cfg: EnvConfig, xs: tuple[float, float], zs: tuple[float, float], pose: tuple, vel: tuple,
             action: Any) -> tuple[tuple, tuple, bool]:
    """The env's kinematics of one step (rate limits, workspace), then the envelope: the new pose, the realised
    velocities, and whether the envelope (not the workspace) held the bucket."""
    dt, dv, dw, vmax, wmax, (wx0, wx1), (wz0, wz1), (a_lo, a_hi) = cfg.motion
    a = np.nan_to_num(np.clip(np.asarray(action, dtype=float).reshape(3), -1.0, 1.0))
    x, z, th = pose
    vx = vel[0] + float(np.clip(a[0] * vmax - vel[0], -dv, dv))
    vz = vel[1] + float(np.clip(a[1] * vmax - vel[1], -dv, dv))
    om = vel[2] + float(np.clip(a[2] * wmax - vel[2], -dw, dw))
    xn, zn = min(max(x + vx * dt, wx0), wx1), min(max(z + vz * dt, wz0), wz1)  # the env's workspace
    thn = min(max(th + om * dt, a_lo), a_hi)
    xc, zc = min(max(xn, xs[0]), xs[1]), min(max(zn, zs[0]), zs[1])  # the envelope within it
    return (xc, zc, thn), ((xc - x) / dt, (zc - z) / dt, (thn - th) / dt), xc != xn or zc != zn


def centred_forces(halves: list[tuple[np.ndarray, np.ndarray]], dt: float) -> np.ndarray:
    """The mean force over the interval centred on each sample (as :meth:`MPMPlant.dig` logs it) from the impulses
    of each step's two halves [N s per metre]."""
    n = len(halves) + 1
    impulse = np.zeros((n, 2))
    window = np.zeros(n)
    for k, (first, second) in enumerate(halves):
        impulse[k] += first
        impulse[k + 1] += second
        window[k] += 0.5 * dt
        window[k + 1] += 0.5 * dt
    return impulse / np.maximum(window, 1e-12)[:, None]


def dig_closed_loop(plant: Any, path: BucketPath, pile: Pile, soil: SoilParams | str, seed: int,
                    controller: Any) -> CycleLog:
    """One cycle of ``controller`` (``obs -> action`` of the bucket-loading env) in the MPM ``plant``, from the
    first pose of ``path`` within its envelope; see the module docstring."""
    cfg = getattr(controller, "env_config", None) or loop_env_config()
    if not isinstance(cfg, EnvConfig):
        raise ValueError(f"the controller's env_config must be an EnvConfig, got {type(cfg).__name__}")
    xs, zs, domain = envelope(path, cfg)
    run = plant.begin(domain, pile, soil, seed)
    solver, width, dt, loader = run.solver, plant.bucket.width, cfg.dt, cfg.loader
    try:
        sensors = PlantSensors(cfg, pile, run, plant.shape, width)
        t0 = float(path.t[0])
        pose = (float(path.x[0]), float(path.z[0]), float(path.blade_angle[0]))
        vel = (0.0, 0.0, 0.0)
        positions = run.start_positions
        fill_m, inside = sensors.fill(pose, positions)
        depth = surface_contact(pile, *pose, cfg.bucket.floor_length, cfg.slope_window)[0]
        touched, entered = cycle_progress(False, False, depth > 0.0, fill_m * width, cfg.exit_fill_volume)
        crest = float(np.max(pile.heights))
        poses, fills, halves = [pose], [fill_m], []
        f_t = f_n = 0.0
        end, stalls, above, held = "step limit", 0, 0, 0
        for k in range(1, STEPS_PER_CYCLE + 1):
            action = controller(sensors.observation(pose, vel, fill_m, f_t, f_n, positions, inside))
            new, vel, clipped = env_step(cfg, xs, zs, pose, vel, action)
            held += int(clipped)
            t_prev, t_next = t0 + (k - 1) * dt, t0 + k * dt
            segment = Trajectory(np.array([t_prev, t_next]), np.array([pose[0], new[0]]),
                                 np.array([pose[1], new[1]]), np.array([pose[2], new[2]]))
            first = solver.advance(t_prev + 0.5 * dt, segment)
            second = solver.advance(t_next, segment)
            halves.append((first, second))
            positions = solver.positions()
            fill_m, inside = sensors.fill(new, positions)
            fx, fz = (first + second) / dt * width
            tangential, normal = blade_frame(np.array([fx]), np.array([fz]), np.array([new[2]]))
            f_t, f_n = float(tangential[0]), float(normal[0])
            pose = new
            poses.append(pose)
            fills.append(fill_m)
            depth, _, _, _, height = surface_contact(pile, *pose, cfg.bucket.floor_length, cfg.slope_window)
            over = f_t > loader.max_push_force or f_n > loader.max_lift_force
            above += int(over)
            stalls = stalls + 1 if over else 0
            touched, entered = cycle_progress(touched, entered, depth > 0.0, fill_m * width, cfg.exit_fill_volume)
            if stalls >= cfg.stall_patience:
                end = "stall"
                break
            if cycle_done(touched, entered, pose[1], pose[1] - height, crest, cfg.exit_clearance):
                end = "exit"
                break
        arr = np.array(poses)
        dug = BucketPath(t0 + dt * np.arange(len(arr)), arr[:, 0], arr[:, 1], arr[:, 2],
                         name=f"{path.name} (closed loop in the plant)")
        log = plant.finish(run, dug, centred_forces(halves, dt), np.array(fills))
    finally:
        solver.close()
    log.metadata["closed_loop"] = {
        "end": end, "steps": len(halves), "steps_above_limits": above, "envelope_steps": held,
        "envelope": {"x": list(xs), "z": list(zs)}, "control_rate_hz": 1.0 / dt,
        "controller": getattr(controller, "name", type(controller).__name__),
        "env_force_model": cfg.force_model, "sensor_noise_N": 0.0,
        "first_observation_force": "zero (the bucket at rest out of the soil)",
    }
    if not math.isfinite(float(np.sum(log.tangential))):
        raise ValueError("the closed-loop cycle's forces are not finite")
    return log
