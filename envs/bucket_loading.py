"""The bucket-loading environment: one digging cycle of a wheel loader on the FEE force simulator."""

from __future__ import annotations

import copy
import dataclasses
import inspect
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    GRAVITY,
    CycleLog,
    ParameterError,
    Pile,
    SoilParams,
    SurfaceCarver,
    contact_single,
    soil_forces_single,
)
from wheelloader.estimator.checks import check_optional_int
from wheelloader.estimator.force_models import fee_options_for
from wheelloader.estimator.kinematics import surface_contact
from wheelloader.estimator.learned_plant import LearnedCorrection, learned_correction
from wheelloader.estimator.payload import kept_volume_float
from wheelloader.estimator.pile import node_heights

from .bookkeeping import (
    RESET_OPTIONS,
    cycle_done,
    cycle_progress,
    outside_validity,
    parse_reset_options,
    reward_terms,
    step_work,
)
from .config import (
    NOISE_CHUNK,
    SETTING_NAMES,
    STEPS_PER_CYCLE,
    EnvConfig,
    SoilArgument,
    choose_soil,
    draw_noise_chunk,
    draw_start_pose,
    next_pile,
    settings_parameters,
)
from .cycle_history import CycleHistory, record_arrays, to_cycle_log
from .rllib_env_config import accepts_env_config
from .truth import as_truth, model_excess, stone_step

__all__ = ["RESET_OPTIONS", "BucketLoadingEnv", "SoilArgument"]

def env_config_episode_limit(settings: dict[str, Any]) -> dict[str, Any]:
    """Built from an env_config (RLlib's way, no ``gym.make`` and so no ``TimeLimit`` wrapper), an episode
    ends at the registered limit unless the config says otherwise: :data:`~wheelloader.envs.config.
    STEPS_PER_CYCLE` steps per cycle."""
    if "max_episode_steps" not in settings:
        cycles = settings.get("cycles_per_episode", 1)
        if isinstance(cycles, int) and not isinstance(cycles, bool) and cycles >= 1:
            settings = {**settings, "max_episode_steps": STEPS_PER_CYCLE * cycles}
    return settings


#: The acceleration of a step without one (the paper's model, or a stalled step) [m/s^2].
_AT_REST = (0.0, 0.0)


def _pick(condition: Any, a: Any, b: Any) -> Any:
    """``where`` for Python scalars."""
    return a if condition else b


class BucketLoadingEnv(gym.Env[np.ndarray, np.ndarray]):
    r"""One bucket-loading (digging) cycle of a wheel loader, forces from the modified FEE.

    ## Description

    A quasi-2D wheel-loader bucket digs into a pile. The agent commands the
    bucket-tip velocity along x (horizontal, into the pile) and z (up) and the
    bucket tilt (curl) rate; the motion is kinematic and rate-limited. The
    tip carves the pile surface and fills the bucket (up to its capacity;
    the rest spills). The soil forces on the blade, tangential ``F_T``
    (eq 16) and normal ``F_N`` (eq 17), come from the project's force model
    (:func:`~wheelloader.estimator.soil_forces_single`) evaluated with a
    hidden "true" soil; the agent sees them with Gaussian sensor noise. The
    same env, reset with calibrated parameters and without noise (see
    :meth:`make_twin`), is the digital twin on which a planner can rehearse.

    Depth is measured to the pile surface as it was at the start of the cycle;
    fill and the look-ahead surface heights come from the carved surface.

    ``force_model`` selects the plant's model, as ``force_model=`` does in
    :func:`~wheelloader.estimator.calibrate`, :func:`~wheelloader.estimator.predict`
    and the planner: ``"fee"`` (default, the paper's FEE: the fill is the carved
    volume up to the capacity, no force out of the soil) or ``"fee-payload"``
    (the payload as a state, :mod:`~wheelloader.estimator.payload`: the fill is
    the kept soil, ``kept_volume`` of the volume removed this cycle, saturating
    smoothly at the heaped capacity; in soil the FEE's surcharge is the carved
    fill's, and as the tip leaves the soil the kept soil's weight and inertia
    (the step's acceleration) take over, so a loaded bucket out of the soil
    still feels its load), or ``"fee-learned"`` (``"fee-payload"`` plus the
    correction learned from the continuum, :mod:`~wheelloader.estimator.learned`,
    at the step's pose, fills and realised speed). The fill in the observation,
    ``info`` and the reward is the model's fill; ``info["carved_volume"]`` is
    the carved volume under every model.

    ## Action Space

    ``Box(-1, 1, (3,), float32)``, normalised and clipped to [-1, 1]:

    | Num | Action                          | Scale                              | Unit  |
    |-----|---------------------------------|------------------------------------|-------|
    | 0   | commanded tip velocity along x  | ``loader.max_speed`` (1.0)         | m/s   |
    | 1   | commanded tip velocity along z  | ``loader.max_speed`` (1.0)         | m/s   |
    | 2   | commanded tilt (curl) rate      | ``loader.max_tilt_rate`` (1.0)     | rad/s |

    The realised velocity moves towards the command by at most
    ``loader.max_acceleration * dt`` (2 m/s^2) per axis and
    ``max_tilt_acceleration * dt`` (4 rad/s^2) for the tilt. The tip stays in
    the workspace: x over the pile grid, z from the ground to the crest plus
    ``lift_headroom``, blade angle within ``blade_angle_limits``.

    ## Observation Space

    ``Box(low, high, (12 + len(lookahead),), float32)``, all finite bounds:

    | Num | Observation                                      | Unit  |
    |-----|--------------------------------------------------|-------|
    | 0   | tip x                                            | m     |
    | 1   | tip z                                            | m     |
    | 2   | blade angle (above +x, tip-down negative)        | rad   |
    | 3   | tip velocity along x                             | m/s   |
    | 4   | tip velocity along z                             | m/s   |
    | 5   | tilt rate                                        | rad/s |
    | 6   | depth below the start-of-cycle surface           | m     |
    | 7   | rho, blade angle relative to the local surface   | rad   |
    | 8   | alpha, local slope of the start surface          | rad   |
    | 9   | bucket fill fraction (fill / capacity)           | -     |
    | 10  | last measured F_T (noisy, clipped to sensor range)| kN   |
    | 11  | last measured F_N (noisy, clipped to sensor range)| kN   |
    | 12+ | carved surface height at ``x + lookahead[i]`` minus tip z | m |

    ## Rewards

    ``reward = reward_fill + reward_energy + reward_validity + reward_stall
    + reward_force`` (each term is in ``info``; weights in
    :class:`~wheelloader.envs.config.RewardWeights`):

    * ``reward_fill = fill * dV_bucket / capacity`` (fill gained this step; the
      kept soil under ``"fee-payload"``);
    * ``reward_energy = -energy * (dE_soil + dE_payload)``: mechanical work
      done on the soil, ``max(0, F_T ds_t + F_N ds_n)`` with the tip
      displacement resolved along and across the blade, plus lifting work on
      the payload, ``max(0, W_load dz)`` [J];
    * ``reward_validity = -validity`` on steps with the tip in soil outside
      the model's validity domain (force-model flags other than "out of soil");
    * ``reward_stall = -stall`` on stalled steps;
    * ``reward_force = -force * (max(0, F_T/F_push - s) + max(0, F_N/F_lift - s))``
      with ``s = force_soft_limit``.

    ## Starting State

    The tip starts at ``start_pose`` (default: 0.10 m before the pile toe,
    0.03 m above the ground, blade angle -5 deg) plus uniform noise of
    ``start_noise`` half-widths (0.03 m, 0.01 m, 2 deg), at rest, with an
    empty bucket. The pile is the configured one, or the carved pile of the
    previous cycle when ``keep_pile`` is set.

    ## Episode End

    * Termination, cycle done: the tip has been in soil and is now more
      than ``exit_clearance`` (0.02 m) above the start surface. With
      ``exit_min_fill`` > 0 (a fraction of the bucket's capacity; default 0)
      the tip must also have been in soil with at least that much loaded, so
      that grazing the thin layer a carved pile leaves on the ground does not
      end a cycle (the cycle-to-cycle loop uses 0.05); a cycle that touched
      soil but loaded less then ends once the tip is more than
      ``exit_clearance`` above the pile's crest. In the multi-cycle
      variant the next cycle starts instead (empty bucket, carved pile) until
      ``cycles_per_episode`` cycles are done.
    * Termination, stall: the force needed exceeds the loader's limit,
      ``F_T > loader.max_push_force`` (20 kN) or ``F_N > loader.max_lift_force``
      (25 kN), for ``stall_patience`` consecutive steps (default 1). A stalled
      step does not move the bucket (pose held, velocity zeroed, carving undone).
    * Truncation: ``max_episode_steps`` from :func:`gymnasium.register`
      (600 steps = 10 s at 60 Hz for ``BucketLoading-v0``), or the env's own
      ``max_episode_steps`` argument.

    ## Arguments

    ``gym.make("wheelloader/BucketLoading-v0", ...)`` (or ``BucketLoadingEnv(...)``) with
    the keyword-only arguments (same names and defaults as
    :class:`~wheelloader.envs.config.EnvConfig`, the one list of the settings, which validates them):

    * ``soil``: hidden soil: preset name (default ``"gravel"``),
      :class:`SoilParams`, parameter dict, ``"random"`` (uniform over the
      presets), list of soils, or a range dict ``{"phi": (lo, hi), ...,
      "base": "sand"}`` / :class:`~wheelloader.envs.config.SoilRandomization`
      for domain randomisation (resampled at every reset by default).
    * ``pile``: :class:`Pile` or ``{"shape": "trapezoid"|"ideal_slope", ...}``
      (default: 30 deg trapezoid, 1 m high).
    * ``loader``, ``bucket``: :class:`Loader`, :class:`Bucket` or dicts.
    * ``control_rate``: steps per second [Hz] (default 60).
    * ``sensor_noise``: std of the additive force noise [N] (default 150);
      ``sensor_range``: saturation of the force sensor [N] (default 100 kN).
    * ``reward_weights``: :class:`RewardWeights` or dict.
    * ``truth``: :class:`~wheelloader.envs.truth.TruthOptions` or dict:
      compaction, rate-dependent resistance, stones, soil drift (all off).
    * ``start_pose``, ``start_noise``, ``blade_angle_limits``,
      ``lift_headroom`` [m], ``max_tilt_acceleration`` [rad/s^2],
      ``stall_patience`` [steps], ``exit_clearance`` [m], ``exit_min_fill``
      [fraction of capacity], ``lookahead``
      distances [m], ``slope_window`` [m].
    * ``keep_pile`` (default False), ``relax`` (False, True = relax to the
      soil's friction angle, or a repose angle [rad]), ``relax_iterations``
      (sweeps of :meth:`Pile.relaxed` per new cycle, default 500: a partial
      slump of steep carved walls), ``cycles_per_episode`` (default 1).
    * ``force_model``: ``"fee"`` (default), ``"fee-payload"`` or
      ``"fee-learned"`` (:data:`~wheelloader.estimator.FORCE_MODELS`); ``payload``:
      :class:`~wheelloader.estimator.PayloadOptions` or dict for the payload
      models (default :data:`~wheelloader.estimator.DEFAULT_PAYLOAD`, under
      ``"fee-learned"`` the payload fitted with its correction).
    * ``render_mode``: ``None``, ``"rgb_array"`` or ``"human"``.
    * ``max_episode_steps``: truncate the episode after this many steps
      (default None: ``gym.make`` adds its ``TimeLimit`` wrapper instead).

    RLlib's way works too: a mapping (a dict or RLlib's ``EnvContext``) as
    the first positional argument holds the same settings,
    ``BucketLoadingEnv({"soil": "random"})``, and may be combined with
    keyword arguments; an unknown key, or a key given both ways with
    different values, raises :class:`ParameterError`. Built from such a
    mapping the env truncates at 600 steps per cycle (the registered limit)
    unless it sets ``max_episode_steps``. By id without an import, in a
    fresh process (RLlib's workers): ``"wheelloader.envs:wheelloader/BucketLoading-v0"``.

    ``reset(options=...)`` accepts ``keep_pile`` (bool), ``relax`` (bool or
    repose angle in (0, pi/2) rad), ``soil`` (``"keep"``, ``"resample"`` or a
    soil, e.g. calibrated parameters), ``truth`` and ``sensor_noise`` (finite,
    >= 0 N); anything else raises :class:`ParameterError` naming the option
    (:func:`~wheelloader.envs.bookkeeping.parse_reset_options`, shared with
    the batched env). Finished cycles are available as
    :class:`~wheelloader.estimator.CycleLog` through :meth:`last_cycle_log`
    and :meth:`cycle_logs`; :attr:`cycle_ends` says why each ended.

    The step's work, reward terms and cycle-end rule are those of
    :mod:`wheelloader.envs.bookkeeping`, the same functions the batched env,
    :func:`~wheelloader.planner.verify_plan` and the planner's NLP use.

    ## Version History

    * v0: initial version. Before the first release the end-of-cycle rule
      gained the opt-in ``exit_min_fill`` (default 0: the first-exit rule);
      reset options are validated strictly (``keep_pile`` must be a bool);
      the dynamics did not change.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 60}

    @accepts_env_config(known=lambda: _SINGLE_ENV_KEYS, defaults=env_config_episode_limit)
    def __init__(self, render_mode: str | None = None, *, max_episode_steps: int | None = None,
                 **settings: Any) -> None:
        # The settings are EnvConfig's fields (the one list); the signature below names them all.
        self.max_episode_steps = check_optional_int("max_episode_steps", max_episode_steps)
        self.cfg: EnvConfig = EnvConfig.from_kwargs(type(self).__name__, **settings)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ParameterError(f"render_mode must be one of {self.metadata['render_modes']} or None, "
                                 f"got {render_mode!r}")
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(self.cfg.control_rate))}
        self.action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        low, high = self.cfg.obs_bounds()
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self._renderer = None
        self._soil: SoilParams | None = None
        self._start_pile: Pile = self.cfg.pile
        self._carver: SurfaceCarver | None = None
        self._cycles = CycleHistory()
        self.max_logged_cycles = 20
        self._seed: int | None = None
        self._samples: list[tuple] | None = None  # the current cycle's samples (RECORD_KEYS order)
        self._learned_soil: SoilParams | None = None  # the soil of _learned ("fee-learned" only)
        self._learned: LearnedCorrection | None = None

    @property
    def soil(self) -> SoilParams:
        """The soil the simulator uses now (hidden truth, or calibrated parameters in a twin)."""
        if self._soil is None:
            raise ParameterError("call reset() before reading the soil")
        return self._soil

    @property
    def start_pile(self) -> Pile:
        """The surface when the current cycle started (depth is measured to it; carved by earlier cycles)."""
        return self._start_pile

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        request = parse_reset_options(options, self.cfg)
        super().reset(seed=seed)
        if seed is not None:
            self._seed = int(seed)
        if request.config_changed:
            self.cfg = request.config
            self._learned_soil = None
        if self._samples is not None and len(self._samples) >= 2:
            self._finish_cycle("reset")
        carved = self._carver.pile() if self._carver is not None else None
        self._soil = choose_soil(self.cfg, self._soil, request.soil, self.np_random)
        self._start_cycle(next_pile(self.cfg, carved, request.keep_pile, request.relax, self._soil), new_episode=True)
        self._k = 0
        self._draw_noise()
        self._cycle_count = 0
        f_t, f_n = self._initial_forces(0)
        obs = self._observation(f_t, f_n)
        if self.render_mode == "human":
            self.render()
        return obs, {"soil": self._soil.to_dict(), "cycle": self._cycle_count}

    def _start_cycle(self, pile: Pile, new_episode: bool) -> None:
        """Fresh bucket at a new start pose on ``pile`` (draws the start pose from np_random)."""
        self._start_pile = pile
        cfg = self.cfg
        self._carver = SurfaceCarver(pile, cfg.bucket.width, cfg.bucket.capacity, 0.0)
        self._x, self._z, self._th = draw_start_pose(cfg, self.np_random)
        self._vx = self._vz = self._om = 0.0
        self._stall_count = 0
        self._stone = 0.0
        self._beta: float | None = None
        self._exit_angle = self._th  # the blade angle the payload's heap sees: current in soil, held after exit
        self._energy_soil = self._energy_payload = 0.0
        self._fill = 0.0  # the bucket's fill [m^3]: the carved volume ("fee") or the payload's kept soil
        self._cycle_t = 0
        self._samples = []
        depth, rho, alpha, lt = contact_single(pile, self._x, self._z, self._th, cfg.bucket.floor_length,
                                               cfg.slope_window)
        self._depth, self._rho, self._alpha, self._lt = depth, rho, alpha, lt
        self._touched, self._entered = cycle_progress(False, False, depth > 0.0, 0.0, cfg.exit_fill_volume)
        self._crest = float(np.max(pile.heights))

    def _initial_forces(self, k: int) -> tuple[float, float]:
        """Forces at the start pose (measured with the noise of step index ``k``), logged as sample 0."""
        f_t, f_n, beta, flags = soil_forces_single(self._soil, self._depth, self._rho, self._alpha, self._lt, 0.0,
                                                   self.cfg.bucket, fee_options_for(self.cfg.force_model))
        learned = self._learned_at(self._soil) if self.cfg.payload is not None else None
        if learned is not None:  # "fee-learned" at rest with an empty bucket
            d_t, d_n = learned.single(self._depth, self._rho, self._alpha, self._th, 0.0, 0.0, 0.0)
            f_t, f_n = f_t + d_t, f_n + d_n
        if self._depth > 0.0:
            self._beta = beta
        noise = self._noise_n[k % NOISE_CHUNK]
        m_t = self._measure(f_t, noise[0])
        m_n = self._measure(f_n, noise[1])
        if self._samples is not None:
            self._samples.append((self._cycle_t * self.cfg.dt, self._x, self._z, self._th, m_t, m_n,
                                  self._fill, f_t, f_n, flags))
        self._mt, self._mn = m_t, m_n
        return m_t, m_n

    def _draw_noise(self) -> None:
        """The next :data:`NOISE_CHUNK` steps' noise, as lists of Python floats (cheap to index)."""
        normal, uniform = draw_noise_chunk(self.np_random)
        self._noise_n, self._noise_u = normal.tolist(), uniform.tolist()

    def _measure(self, force: float, z: float) -> float:
        value = force + self.cfg.sensor_noise * z
        r = self.cfg.sensor_range
        return -r if value < -r else (r if value > r else value)

    # ------------------------------------------------------------------ step
    def step(self, action: np.ndarray):
        carver = self._carver
        if carver is None:
            raise ParameterError("call reset() before step()")
        cfg = self.cfg
        ld = cfg.loader
        x, z, th = self._x, self._z, self._th
        xn, zn, thn, vx, vz, om = self._move(action)
        before = carver.fill, carver.spilled, carver.removed  # carver.state()
        fill0 = self._fill
        payload = cfg.payload
        changes: list = []
        carver.cut_segment(x, z, xn, zn, changes)
        k = self._k = self._k + 1
        j = k % NOISE_CHUNK
        if j == 0:
            self._draw_noise()
        acc = _AT_REST if payload is None else ((vx - self._vx) / cfg.dt, (vz - self._vz) / cfg.dt)
        depth, rho, alpha, height, w_load, f_t, f_n, beta, flags = self._plant(xn, zn, thn, x, z, j, acc)
        stalled = f_t > ld.max_push_force or f_n > ld.max_lift_force
        if stalled:  # the bucket does not move: carving undone, pose held, velocity zeroed (weight only)
            carver.restore(changes, before)
            xn, zn, thn, vx, vz, om = x, z, th, 0.0, 0.0, 0.0
            depth, rho, alpha, height, w_load, f_t, f_n, beta, flags = self._plant(x, z, th, x, z, -1, _AT_REST)
            self._stall_count += 1
        else:
            self._stall_count = 0
        if depth > 0.0:
            self._beta = beta
            self._exit_angle = thn
        fill = self._fill = (carver.fill if payload is None
                             else kept_volume_float(carver.removed, cfg.bucket.capacity, payload, 0.0,
                                                    self._exit_angle))
        e_soil, e_pay = step_work(f_t, f_n, xn - x, zn - z, thn, w_load, cos=math.cos, sin=math.sin)
        self._energy_soil += e_soil
        self._energy_payload += e_pay
        sigma, r = cfg.sensor_noise, cfg.sensor_range
        noise_t, noise_n = self._noise_n[j]
        m_t = f_t + sigma * noise_t
        m_t = -r if m_t < -r else (r if m_t > r else m_t)
        m_n = f_n + sigma * noise_n
        m_n = -r if m_n < -r else (r if m_n > r else m_n)
        self._x, self._z, self._th, self._vx, self._vz, self._om = xn, zn, thn, vx, vz, om
        self._depth, self._rho, self._alpha = depth, rho, alpha
        self._mt, self._mn = m_t, m_n
        self._cycle_t += 1
        if self._samples is not None:  # stepping after the end of an episode: nothing is logged
            self._samples.append((self._cycle_t * cfg.dt, xn, zn, thn, m_t, m_n, fill, f_t, f_n, flags))
        cap = cfg.bucket.capacity
        r_fill, r_energy, r_valid, r_stall, r_force = reward_terms(  # RewardTerms, unpacked once
            cfg.reward_weights, cap, ld.max_push_force, ld.max_lift_force, fill - fill0, e_soil + e_pay,
            outside_validity(depth, flags), stalled, f_t, f_n)
        # cycle end (one rule for every backend): out of the soil after loading
        self._touched, self._entered = cycle_progress(self._touched, self._entered, depth > 0.0, fill,
                                                      cfg.exit_fill_volume)
        done = cycle_done(self._touched, self._entered, zn, zn - height, self._crest, cfg.exit_clearance)
        info = {
            "reward_fill": r_fill, "reward_energy": r_energy, "reward_validity": r_valid,
            "reward_stall": r_stall, "reward_force": r_force,
            "fill_volume": fill, "fill_fraction": fill / cap, "carved_volume": carver.fill, "spilled": carver.spilled,
            "force_tangential": f_t, "force_normal": f_n, "measured_tangential": m_t, "measured_normal": m_n,
            "energy_soil": self._energy_soil, "energy_payload": self._energy_payload,
            "depth": depth, "flags": flags, "stalled": stalled, "cycle_done": done,
            "cycle": self._cycle_count,
        }
        terminated = (self._end_cycle(done) if done or self._stall_count >= cfg.stall_patience else False)
        obs = self._observation(self._mt, self._mn)  # a new cycle of the multi-cycle variant measured its start
        if self.render_mode == "human":
            self.render()
        truncated = (not terminated and self.max_episode_steps is not None
                     and self._k >= self.max_episode_steps)
        return obs, r_fill + r_energy + r_valid + r_stall + r_force, terminated, truncated, info  # terms.total()

    def _move(self, action: np.ndarray) -> tuple[float, float, float, float, float, float]:
        """Kinematics: the action (clipped to [-1, 1], NaN counts as 0) moves the rate-limited velocity;
        the new pose is clipped to the workspace. Returns ``(x, z, theta, vx, vz, omega)`` (not yet stored)."""
        if type(action) is np.ndarray and action.shape == (3,) and action.dtype.kind == "f":  # the common case
            a0, a1, a2 = action.tolist()
        else:
            try:
                a0, a1, a2 = np.asarray(action, dtype=np.float64).reshape(3).tolist()
            except (ValueError, TypeError):
                raise ParameterError(f"action must be 3 numbers (x, z and blade-angle rate commands in [-1, 1]), got "
                                     f"{np.shape(action)} {action!r:.60}") from None
        a0 = 0.0 if a0 != a0 else (-1.0 if a0 < -1.0 else (1.0 if a0 > 1.0 else a0))
        a1 = 0.0 if a1 != a1 else (-1.0 if a1 < -1.0 else (1.0 if a1 > 1.0 else a1))
        a2 = 0.0 if a2 != a2 else (-1.0 if a2 < -1.0 else (1.0 if a2 > 1.0 else a2))
        dt, dv, dw, vmax, wmax, (x0, x1), (z0, z1), (lo, hi) = self.cfg.motion
        x, z, th = self._x, self._z, self._th
        d = a0 * vmax - self._vx
        vx = self._vx + (-dv if d < -dv else (dv if d > dv else d))
        d = a1 * vmax - self._vz
        vz = self._vz + (-dv if d < -dv else (dv if d > dv else d))
        d = a2 * wmax - self._om
        om = self._om + (-dw if d < -dw else (dw if d > dw else d))
        xn = x + vx * dt
        xn = x0 if xn < x0 else (x1 if xn > x1 else xn)
        zn = z + vz * dt
        zn = z0 if zn < z0 else (z1 if zn > z1 else zn)
        thn = th + om * dt
        thn = lo if thn < lo else (hi if thn > hi else thn)
        return xn, zn, thn, (xn - x) / dt, (zn - z) / dt, (thn - th) / dt

    def _plant(self, x: float, z: float, th: float, x_before: float, z_before: float, j: int,
               acceleration: tuple[float, float]) -> tuple:
        """Contact and plant forces at a pose with the current fill: the shared model (depth to the
        start-of-cycle surface), then the truth beyond the model (``j < 0``: no new stone; the step came from
        ``(x_before, z_before)``; ``acceleration``: the tip's this step [m/s^2], the carried load's inertia under
        ``"fee-payload"``).

        Returns ``(depth, rho, alpha, surface height, W_load, F_T, F_N, beta, flags)``; ``W_load`` [N] is the
        weight of the bucket's fill (the payload's kept soil under ``"fee-payload"``, whose surcharge in soil
        is the carved fill's, as the estimator's model has it).
        """
        cfg = self.cfg
        soil, bucket = self._soil, cfg.bucket
        depth, rho, alpha, lt, height = surface_contact(self._start_pile, x, z, th, bucket.floor_length,
                                                        cfg.slope_window)
        w_load = soil.gamma * GRAVITY * self._carver.fill
        payload = cfg.payload
        if payload is None:
            f_t, f_n, beta, flags = soil_forces_single(soil, depth, rho, alpha, lt, w_load, bucket, DEFAULT_OPTIONS,
                                                       self._beta)
        else:  # "fee-payload": the kept soil's weight and inertia take over from the surcharge at exit
            kept = kept_volume_float(self._carver.removed, bucket.capacity, payload, 0.0,
                                     th if depth > 0.0 else self._exit_angle)
            carried = soil.gamma * GRAVITY * kept
            f_t, f_n, beta, flags = soil_forces_single(soil, depth, rho, alpha, lt, w_load, bucket, cfg.model_options,
                                                       self._beta, acceleration=acceleration, carried_weight=carried)
            w_load = carried
            learned = self._learned if self._learned_soil is soil else self._learned_at(soil)
            if learned is not None:  # "fee-learned": the learned correction at this step's speed
                d_t, d_n = learned.single(depth, rho, alpha, th, self._carver.fill, kept,
                                          math.hypot(x - x_before, z - z_before) / cfg.dt)
                f_t, f_n = f_t + d_t, f_n + d_n
        if cfg.truth_active:
            dist = math.hypot(x - x_before, z - z_before)
            f_t, f_n = self._truth_forces(f_t, f_n, depth, dist / cfg.dt, dist, j)
        return depth, rho, alpha, height, w_load, f_t, f_n, beta, flags

    def _learned_at(self, soil: SoilParams) -> LearnedCorrection | None:
        """The learned correction at ``soil`` under ``"fee-learned"`` (made once per soil), else None."""
        if self._learned_soil is not soil or (self._learned is not None) != (self.cfg.force_model == "fee-learned"):
            self._learned_soil = soil
            self._learned = (learned_correction(soil, self.cfg.bucket) if self.cfg.force_model == "fee-learned"
                             else None)
        return self._learned

    def _end_cycle(self, cycle_done: bool) -> bool:
        """Close a stalled or finished cycle (in the multi-cycle variant start the next); whether to terminate."""
        cfg = self.cfg
        if self._stall_count >= cfg.stall_patience:
            self._finish_cycle("stall")
            return True
        self._finish_cycle("exit")
        self._cycle_count += 1
        if self._cycle_count >= cfg.cycles_per_episode:
            return True
        carved = self._carver.pile()
        self._soil = choose_soil(cfg, self._soil, "keep", self.np_random)
        self._start_cycle(next_pile(cfg, carved, True, cfg.relax, self._soil), new_episode=False)
        self._initial_forces(self._k)  # the new cycle's first sample, measured with this step's noise
        return False

    def _truth_forces(self, f_t: float, f_n: float, depth: float, speed: float, dist: float,
                      j: int) -> tuple[float, float]:
        """Add the beyond-model effects of :mod:`wheelloader.envs.truth` (j < 0: no new stone)."""
        tr = self.cfg.truth
        f_t, f_n = model_excess(tr, f_t, f_n, depth, speed, self.cfg.bucket.width, where=_pick)
        if j >= 0:
            u = self._noise_u[j]
            self._stone = stone_step(tr, self._stone, depth, dist, u[0], u[1], self.cfg.stone_decay, where=_pick,
                                     log1p=math.log1p)
        return f_t + self._stone, f_n + 0.5 * self._stone

    # ------------------------------------------------------------------ observation
    def _observation(self, m_t: float, m_n: float) -> np.ndarray:
        x, z = self._x, self._z
        carver = self._carver
        cfg = self.cfg
        vals = [x, z, self._th, self._vx, self._vz, self._om, self._depth, self._rho, self._alpha,
                self._fill / cfg.bucket.capacity, m_t * 1e-3, m_n * 1e-3]
        vals += node_heights(carver.nodes, carver.x0, carver.spacing, x, cfg.lookahead, z)  # surface minus tip z
        low, high = cfg.observation_limits  # float32 bounds: clipping after the cast equals clipping before it
        obs = np.fromiter(vals, np.float32, len(vals))  # np.array(vals, dtype=np.float32), the same values, faster
        np.maximum(obs, low, out=obs)
        return np.minimum(obs, high, out=obs)

    # ------------------------------------------------------------------ cycle logs
    def _finish_cycle(self, reason: str) -> None:
        samples = self._samples
        self._samples = None
        if samples is None or len(samples) < 2:
            return
        self._cycles.add(record_arrays(samples), self.max_logged_cycles, pile=self._start_pile,
                         pile_after=self._carver.pile(), soil=self._soil, reason=reason, seed=self._seed,
                         cycle=self._cycle_count, energy_soil=self._energy_soil, energy_payload=self._energy_payload)

    @property
    def cycle_ends(self) -> tuple[str, ...]:
        """Why each kept finished cycle ended (``"exit"``, ``"stall"`` or ``"reset"``), oldest first."""
        return self._cycles.ends

    def episode_record(self, index: int = -1, current: bool = False) -> dict[str, Any]:
        """Raw arrays of a finished cycle (``index`` into the kept cycles) or of the current one.

        Keys (:data:`~wheelloader.envs.cycle_history.RECORD_KEYS`): ``t, x, z, blade_angle`` (path),
        ``F_T, F_N`` (measured), ``fill`` [m^3], ``true_F_T, true_F_N`` (noise-free plant forces), ``flags``.
        """
        if current:
            if self._samples is None:
                raise ParameterError("no cycle in progress")
            return record_arrays(self._samples)
        return self._cycles.record(index)

    def last_cycle_log(self) -> CycleLog:
        """The most recent finished cycle as a :class:`~wheelloader.estimator.CycleLog`.

        Forces are the measured (noisy) ones; ``pile`` is the surface at the
        start of the cycle, ``pile_after`` the carved one, ``fill_volume`` the
        bucket fill per sample; ``metadata`` holds the true soil, the seed,
        why the cycle ended and the env settings.
        """
        if not self._cycles:
            raise ParameterError("no finished cycle yet: step until termination (or reset) first")
        return to_cycle_log(self._cycles[-1], self.cfg)

    def cycle_logs(self) -> list[CycleLog]:
        """All kept finished cycles (at most ``max_logged_cycles``), oldest first, as CycleLogs."""
        return [to_cycle_log(e, self.cfg) for e in self._cycles]

    # ------------------------------------------------------------------ twin
    def make_twin(self, soil: SoilParams | str | dict | None = None) -> BucketLoadingEnv:
        """A copy of this env as digital twin: simulator soil ``soil`` (default: the current one),
        no sensor noise, no beyond-model effects, same pile state. Call ``reset(options={"keep_pile": True})``
        on it to start a cycle on the current carved pile."""
        twin = copy.deepcopy(self)
        twin.cfg = dataclasses.replace(twin.cfg, sensor_noise=0.0, truth=as_truth(None))
        if soil is not None:
            from wheelloader.estimator import as_soil

            twin._soil = as_soil(soil)
            twin.cfg = dataclasses.replace(twin.cfg, soil=twin._soil)
        twin.render_mode = None
        return twin

    # ------------------------------------------------------------------ render
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        from .rendering import EnvRenderer

        if self._renderer is None:
            self._renderer = EnvRenderer(self.render_mode, self.cfg)
        return self._renderer.draw(self.render_state())

    def render_state(self) -> dict[str, Any]:
        """What the renderer draws (plain data)."""
        return {
            "pile": self.cfg.pile, "start_pile": self._start_pile, "carved": self._carver.pile(),
            "x": self._x, "z": self._z, "blade_angle": self._th, "fill": self._fill,
            "capacity": self.cfg.bucket.capacity, "F_T": self._mt, "F_N": self._mn,
            "floor_length": self.cfg.bucket.floor_length, "time": self._cycle_t * self.cfg.dt,
            "limits": (self.cfg.loader.max_push_force, self.cfg.loader.max_lift_force),
        }

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state


def _signature() -> inspect.Signature:
    """``__init__``'s signature: ``render_mode``, the settings of :class:`EnvConfig` (keyword-only, typed, with
    their defaults) and ``max_episode_steps``."""
    own = inspect.signature(BucketLoadingEnv.__init__.__wrapped__).parameters
    return inspect.Signature([own["self"], own["render_mode"], *settings_parameters(), own["max_episode_steps"]])


BucketLoadingEnv.__init__.__signature__ = _signature()
#: Keys an env_config of :class:`BucketLoadingEnv` may hold: its keyword arguments (with ``render_mode``).
_SINGLE_ENV_KEYS: tuple[str, ...] = ("render_mode", *SETTING_NAMES, "max_episode_steps")
