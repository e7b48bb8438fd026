"""NumPy-batched bucket-loading env: many envs stepped in one process (``gym.make_vec``).

Same dynamics, forces, rewards and random streams as
:class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv`: sub-env ``i``
reset with ``seed`` behaves like a single env reset with ``seed + i`` and
given the same actions. Forces come from the shared vectorised model
:func:`~wheelloader.estimator.soil_forces`, called once per distinct soil;
per-env pile surfaces are rows of 2-D height arrays.

Gymnasium's vector API, checked step by step against ``SyncVectorEnv`` of
single envs: the three autoreset modes (``autoreset_mode=`` ``NEXT_STEP``,
the default, ``SAME_STEP`` with ``final_obs`` / ``final_info``, and
``DISABLED``), ``reset(seed=..., options=...)`` with the single env's reset
options plus ``reset_mask`` (partial reset), reset and step ``info`` with the
single env's keys and a ``_key`` mask each, ``get_attr`` / ``set_attr`` /
``call`` (the single env's public methods and per-sub-env attributes:
``last_cycle_log``, ``cycle_logs``, ``episode_record``, ``cycle_ends``,
``render_state``, ``soil``, ``start_pile``, ``np_random``,
``np_random_seed``) and ``render`` (one frame per sub-env).

Not supported here (use ``gym.make_vec(..., vectorization_mode="sync")``):
``cycles_per_episode > 1`` and twins (``make_twin``).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wheelloader.estimator import (
    FLAG_OUT_OF_SOIL,
    GRAVITY,
    ContactState,
    ParameterError,
    SoilParams,
    contact_single,
    soil_forces,
    soil_forces_single,
)
from wheelloader.estimator.checks import check_int
from wheelloader.estimator.force_model import carried_forces
from wheelloader.estimator.force_models import fee_options_for
from wheelloader.estimator.learned_plant import LearnedCorrection, learned_correction
from wheelloader.estimator.payload import kept_volume

from .batched_records import BatchedCycleRecorder
from .batched_surface import BatchedSurfaces
from .bookkeeping import (
    ResetRequest,
    cycle_done,
    cycle_progress,
    outside_validity,
    parse_reset_options,
    reward_terms,
    step_work,
)
from .config import (
    NOISE_CHUNK,
    REWARD_TERMS,
    SETTING_NAMES,
    EnvConfig,
    choose_soil,
    draw_noise_chunk,
    draw_start_pose,
    next_pile,
    settings_parameters,
)
from .rllib_env_config import accepts_env_config
from .truth import model_excess, stone_step
from .vector_api import PER_ENV_ATTRIBUTES, PER_ENV_METHODS, RESET_INFO_KEYS, STEP_INFO_KEYS, VectorApi

__all__ = ["PER_ENV_ATTRIBUTES", "PER_ENV_METHODS", "RESET_INFO_KEYS", "STEP_INFO_KEYS", "BucketLoadingVectorEnv"]



class BucketLoadingVectorEnv(VectorApi, VectorEnv):
    """Batched :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv` (see its docstring).

    Parameters
    ----------
    num_envs : int
        Number of sub-envs.
    max_episode_steps : int
        Truncation limit per sub-env (``gym.make_vec`` passes the registered one).
    render_mode : str or None
        ``"rgb_array"``: :meth:`render` returns one frame per sub-env.
    autoreset_mode : AutoresetMode or str
        ``NEXT_STEP`` (default: the step after an episode end resets that sub-env, reward 0),
        ``SAME_STEP`` (the ending step resets it at once: the returned observation is the new episode's
        first, the last one is in ``info["final_obs"]`` and its step info in ``info["final_info"]``) or
        ``DISABLED`` (reset ended sub-envs yourself with ``reset(options={"reset_mask": ...})``; stepping
        an ended sub-env raises).
    record_cycles : bool
        Keep each sub-env's cycle records for ``call("episode_record")`` and the cycle logs (default True;
        the ring costs ``(max_episode_steps + 1) * 72`` bytes per sub-env).
    **settings
        The single env's settings (:class:`~wheelloader.envs.config.EnvConfig`; ``cycles_per_episode``
        must be 1).

    Notes
    -----
    RLlib's way works too: a mapping (a dict or RLlib's ``EnvContext``) as the
    first positional argument holds the same settings, ``num_envs`` included
    (RLlib's ``gym_env_vectorize_mode="vector_entry_point"`` with the class
    passes ``{**env_config, "num_envs": n}``); an unknown key, or a key given
    both ways with different values, raises ``ParameterError``.

    ``reset(options=...)`` takes the single env's options (one parser,
    :func:`~wheelloader.envs.bookkeeping.parse_reset_options`) plus
    ``reset_mask``. Reset and step ``info`` carry the single env's keys, each
    with a ``_key`` mask (:data:`STEP_INFO_KEYS`, :data:`RESET_INFO_KEYS`), as
    ``SyncVectorEnv`` builds them (``info["soil"]`` is a dict of per-sub-env
    parameter arrays). ``get_attr``, ``set_attr`` and ``call`` give one value
    per sub-env (:data:`PER_ENV_ATTRIBUTES` and :data:`PER_ENV_METHODS` per
    sub-env; other attributes are the batch's). Each sub-env keeps its last
    ``max_logged_cycles`` finished cycles (default 1, against the single env's
    20: a batch of a thousand sub-envs would otherwise hold gigabytes; change
    it with ``set_attr``). SB3 users: :mod:`wheelloader.envs.sb3`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 60, "autoreset_mode": AutoresetMode.NEXT_STEP}

    @accepts_env_config(known=lambda: ("num_envs", "max_episode_steps", "render_mode", "autoreset_mode",
                                       "record_cycles", *SETTING_NAMES))
    def __init__(self, num_envs: int = 1, max_episode_steps: int = 600, render_mode: str | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP, record_cycles: bool = True,
                 **settings: Any) -> None:
        num_envs = check_int("num_envs", num_envs)
        max_episode_steps = check_int("max_episode_steps", max_episode_steps)
        if render_mode not in (None, "rgb_array"):
            raise ParameterError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise ParameterError(f"autoreset_mode must be one of {[m.value for m in AutoresetMode]}, "
                                 f"got {autoreset_mode!r}") from None
        if not isinstance(record_cycles, (bool, np.bool_)):
            raise ParameterError(f"record_cycles must be a bool, got {record_cycles!r}")
        self.cfg = EnvConfig.from_kwargs(type(self).__name__, **settings)
        if self.cfg.cycles_per_episode != 1:
            raise ParameterError("the batched vector env supports cycles_per_episode=1 only; use "
                                 "vectorization_mode='sync' for multi-cycle episodes")
        self.num_envs = num_envs
        self._max_steps = max_episode_steps
        self.render_mode = render_mode
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(self.cfg.control_rate)),
                         "autoreset_mode": mode}
        self.single_action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        low, high = self.cfg.obs_bounds()
        self.single_observation_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._low32, self._high32 = low.astype(np.float32), high.astype(np.float32)
        self._look_col: tuple[Any, np.ndarray] = ((), np.zeros((0, 1)))  # (lookahead, as a column)
        n = num_envs
        self._surf = BatchedSurfaces(self.cfg.pile, n)
        self._records = (BatchedCycleRecorder(n, max_episode_steps, self.cfg.dt, keep=1) if record_cycles
                         else None)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._rng_seeds: list[int | None] = [None] * n
        self._seeds: list[int | None] = [None] * n
        self._soils: list[SoilParams | None] = [None] * n
        self._start_piles: list[Any] = [self.cfg.pile] * n
        self._groups: list[tuple[SoilParams, np.ndarray | slice]] | None = None
        self._learned: dict[SoilParams, LearnedCorrection] = {}  # "fee-learned": its correction by soil
        self._gamma = np.zeros(n)
        self._beta = np.full(n, np.nan)  # each row's last failure angle in soil (the warm start)
        z = np.zeros
        self._x, self._z, self._th = z(n), z(n), z(n)
        self._vx, self._vz, self._om = z(n), z(n), z(n)
        self._depth, self._rho, self._alpha = z(n), z(n), z(n)
        self._fill, self._spilled, self._stone = z(n), z(n), z(n)  # fill: the carved volume up to the capacity
        self._removed = z(n)  # volume removed since the cycle started (the payload's input) [m^3]
        self._exit_angle = z(n)  # the blade angle the payload's heap sees: current in soil, held after exit [rad]
        self._kept = z(n)  # the bucket's fill as the env reports it: _fill, or the payload's kept soil [m^3]
        self._mt, self._mn = z(n), z(n)
        self._e_soil, self._e_pay = z(n), z(n)
        self._entered = np.zeros(n, dtype=bool)
        self._touched = np.zeros(n, dtype=bool)
        self._crest = np.zeros(n)
        self._crest_of: tuple[Any, float] = (None, 0.0)
        self._stall = np.zeros(n, dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._steps = np.zeros(n, dtype=np.int64)
        self._prev_done = np.zeros(n, dtype=bool)
        self._noise_n = np.zeros((n, NOISE_CHUNK, 2))
        self._noise_u = np.zeros((n, NOISE_CHUNK, 2))
        self._noise_base = np.arange(n) * NOISE_CHUNK  # flat index of row i's first pair in _pairs(...)
        self._rows = np.arange(n)
        self._motion: tuple[Any, tuple[np.ndarray, ...]] = (None, ())  # (cfg, _motion_constants())
        self._renderer = None
        self._started = False

    @property
    def max_episode_steps(self) -> int:
        """Truncation limit per sub-env [steps]."""
        return self._max_steps

    @max_episode_steps.setter
    def max_episode_steps(self, value: int) -> None:
        self._max_steps = check_int("max_episode_steps", value)
        if self._records is not None:
            self._records.grow(self._max_steps)

    @property
    def max_logged_cycles(self) -> int:
        """Finished cycles kept per sub-env (default 1)."""
        return self._records.keep if self._records is not None else 0

    @max_logged_cycles.setter
    def max_logged_cycles(self, value: int) -> None:
        self._recorder().keep = check_int("max_logged_cycles", value)

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | Sequence[int | None] | None = None, options: dict[str, Any] | None = None):
        """Reset every sub-env, or with ``options["reset_mask"]`` those where the mask is True.

        Parameters
        ----------
        seed : int, list or None
            ``int``: sub-env ``i`` is seeded with ``seed + i``; a list gives one seed (or None) per
            sub-env; None keeps each sub-env's generator. Only reset sub-envs are seeded.
        options : dict, optional
            The single env's reset options (see
            :func:`~wheelloader.envs.bookkeeping.parse_reset_options`), applied to every reset sub-env,
            plus ``reset_mask``: a boolean array of shape ``(num_envs,)`` with at least one True.
            ``truth`` and ``sensor_noise`` are settings of the whole batch: they need a full reset.

        Returns
        -------
        observations, info
            Observations of every sub-env (unchanged where not reset) and the reset ``info``
            (``soil``, ``cycle`` with their ``_soil``, ``_cycle`` masks).
        """
        n = self.num_envs
        if options is not None and not isinstance(options, Mapping):
            raise ParameterError(f"reset options must be a dict or None, got {type(options).__name__}")
        opts = dict(options or {})
        mask = self._check_reset_mask(opts.pop("reset_mask")) if "reset_mask" in opts else np.ones(n, dtype=bool)
        request = parse_reset_options(opts, self.cfg)
        partial = not mask.all()
        if partial and not self._started:
            raise ParameterError("reset_mask: the first reset must reset every sub-env")
        if partial and request.config_changed:
            raise ParameterError("reset options truth and sensor_noise apply to every sub-env of the batched env: "
                                 "pass them without a partial reset_mask")
        seeds = self._seed_list(seed)
        rows = np.nonzero(mask)[0]
        for i in rows:
            if seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i], self._rng_seeds[i] = seeding.np_random(seeds[i])
            if seeds[i] is not None:
                self._seeds[i] = seeds[i]
        if request.config_changed:
            self.cfg = request.config
            self._learned = {}
        for i in rows:
            self._reset_env(int(i), request)
        self._prev_done[rows] = False
        self._started = True
        return self._observation(), self._reset_info(mask)

    def _reset_env(self, i: int, request: ResetRequest, carved: np.ndarray | None = None) -> None:
        """Reset sub-env ``i`` exactly as BucketLoadingEnv.reset does (same random draws, same order);
        ``carved``: its carved surface when the state rows already moved on."""
        cfg = self.cfg
        rng = self._rngs[i]
        heights = self._surf.carved[i] if carved is None else carved
        if self._records is not None and self._soils[i] is not None:
            self._records.close(i, int(self._steps[i]), "reset", heights, energy_soil=float(self._e_soil[i]),
                                energy_payload=float(self._e_pay[i]))
        keep = request.keep_pile
        kept = self._surf.as_pile(heights) if keep and self._soils[i] is not None else None
        soil = choose_soil(cfg, self._soils[i], request.soil, rng)
        if soil is not self._soils[i]:
            self._groups = None
        self._soils[i] = soil
        self._gamma[i] = soil.gamma
        pile = next_pile(cfg, kept, keep, request.relax, soil)
        self._start_piles[i] = pile
        self._surf.set(i, pile.heights)
        x, z, th = draw_start_pose(cfg, rng)
        self._x[i], self._z[i], self._th[i] = x, z, th
        self._vx[i] = self._vz[i] = self._om[i] = 0.0
        self._fill[i] = self._spilled[i] = self._stone[i] = 0.0
        self._removed[i] = self._kept[i] = 0.0
        self._exit_angle[i] = th
        self._e_soil[i] = self._e_pay[i] = 0.0
        self._stall[i] = 0
        self._k[i] = 0
        self._steps[i] = 0
        depth, rho, alpha, lt = contact_single(pile, x, z, th, cfg.bucket.floor_length, cfg.slope_window)
        self._depth[i], self._rho[i], self._alpha[i] = depth, rho, alpha
        self._touched[i], self._entered[i] = cycle_progress(False, False, depth > 0.0, 0.0, cfg.exit_fill_volume)
        if self._crest_of[0] is not pile:  # the crest of the last start pile (mostly the configured one)
            self._crest_of = (pile, float(np.max(pile.heights)))
        self._crest[i] = self._crest_of[1]
        self._noise_n[i], self._noise_u[i] = draw_noise_chunk(rng)
        f_t, f_n, beta, flags = soil_forces_single(soil, depth, rho, alpha, lt, 0.0, cfg.bucket,
                                                   fee_options_for(cfg.force_model))
        if cfg.force_model == "fee-learned":  # at rest with an empty bucket
            d_t, d_n = self._correction(soil).single(depth, rho, alpha, th, 0.0, 0.0, 0.0)
            f_t, f_n = f_t + d_t, f_n + d_n
        self._beta[i] = beta if depth > 0.0 else np.nan
        r = cfg.sensor_range
        self._mt[i] = m_t = min(max(f_t + cfg.sensor_noise * float(self._noise_n[i, 0, 0]), -r), r)
        self._mn[i] = m_n = min(max(f_n + cfg.sensor_noise * float(self._noise_n[i, 0, 1]), -r), r)
        if self._records is not None:
            self._records.start_cycle(i, (x, z, th, m_t, m_n, 0.0, f_t, f_n, flags), soil=soil, seed=self._seeds[i],
                                      cycle=0, start_pile=pile, start_heights=pile.heights)

    # ------------------------------------------------------------------ forces
    def _soil_groups(self) -> list[tuple[SoilParams, np.ndarray | slice]]:
        if self._groups is None:
            index: dict[SoilParams, list[int]] = {}
            for i, s in enumerate(self._soils):
                index.setdefault(s, []).append(i)
            if len(index) == 1:
                self._groups = [(next(iter(index)), slice(None))]
            else:
                self._groups = [(s, np.asarray(ix)) for s, ix in index.items()]
        return self._groups

    def _forces(self, rows: np.ndarray, depth, rho, alpha, lt, fill):
        """Model forces for the given rows, one soil_forces call per distinct soil, the failure angle warm-started
        from each row's last one in soil (as the single env does). Returns ``(F_T, F_N, flags, beta)`` (beta NaN
        out of soil)."""
        n = rows.size
        # Out of soil the model returns zero forces and FLAG_OUT_OF_SOIL (as soil_forces_single does);
        # only rows in soil go through soil_forces.
        f_t, f_n = np.zeros(n), np.zeros(n)
        flags = np.full(n, FLAG_OUT_OF_SOIL, dtype=np.int64)
        beta = np.full(n, np.nan)
        guess = self._beta[rows]
        ins = depth > 0.0
        bucket = self.cfg.bucket
        options = fee_options_for(self.cfg.force_model)
        groups = self._soil_groups()
        for soil, members in groups:
            if isinstance(members, slice):
                sel: Any = np.nonzero(ins)[0]
            else:
                sel = np.nonzero(ins & np.isin(rows, members))[0]
            if sel.size == 0:
                continue
            state = ContactState(depth[sel], rho[sel], alpha[sel], lt[sel], fill[sel])
            out = soil_forces(soil, state, bucket, options, beta_guess=guess[sel])
            f_t[sel], f_n[sel], flags[sel], beta[sel] = out.tangential, out.normal, out.flags, out.beta
        return f_t, f_n, flags, beta

    def _correction(self, soil: SoilParams) -> LearnedCorrection:
        """``"fee-learned"``'s correction at ``soil`` (made once per soil)."""
        corr = self._learned.get(soil)
        if corr is None:
            corr = self._learned[soil] = learned_correction(soil, self.cfg.bucket)
        return corr

    def _learned_rows(self, rows: np.ndarray, depth, rho, alpha, th, carved, kept, speed):
        """``"fee-learned"``'s correction ``(F_T, F_N)`` on the given rows, one evaluation per distinct soil."""
        d_t, d_n = np.zeros(rows.size), np.zeros(rows.size)
        for soil, members in self._soil_groups():
            sel: Any = slice(None) if isinstance(members, slice) else np.nonzero(np.isin(rows, members))[0]
            d_t[sel], d_n[sel] = self._correction(soil).rows(depth[sel], rho[sel], alpha[sel], th[sel], carved[sel],
                                                             kept[sel], speed[sel])
        return d_t, d_n

    def _truth(self, g, rows, f_t, f_n, depth, speed, dist, j, new_stones: bool):
        """The truth beyond the model (:mod:`.truth`) on the rows' forces (``new_stones``: the step moved)."""
        tr = self.cfg.truth
        f_t, f_n = model_excess(tr, f_t, f_n, depth, speed, self.cfg.bucket.width)
        stone = self._stone[g]
        if new_stones:
            u = _pairs(self._noise_u).take(rows * NOISE_CHUNK + j)  # self._noise_u[rows, j] as (real, imag)
            stone = stone_step(tr, stone, depth, dist, u.real, u.imag, self.cfg.stone_decay)
            self._stone[g] = stone
        return f_t + stone, f_n + 0.5 * stone

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray):
        """Step every sub-env and auto-reset ended ones as ``autoreset_mode`` says.

        ``NEXT_STEP``: a sub-env whose episode ended at the previous step is reset instead (reward 0, not
        terminated; its step-info masks False, its reset info in ``info``). ``SAME_STEP``: a sub-env whose
        episode ends now is reset at once; ``info["final_obs"]`` and ``info["final_info"]`` hold its last
        observation and step info. ``DISABLED``: stepping an ended sub-env before ``reset`` raises.
        """
        if not self._started:
            raise ParameterError("call reset() before step()")
        n = self.num_envs
        try:
            acts = np.asarray(actions, dtype=np.float64).reshape(n, 3)
        except (ValueError, TypeError):
            raise ParameterError(f"actions must be {n} x 3 numbers (one x, z, blade-angle rate command per env), "
                                 f"got shape {np.shape(actions)}") from None
        mode = self.autoreset_mode
        pending = self._prev_done
        any_pending = bool(pending.any())
        if any_pending and mode is AutoresetMode.DISABLED:
            raise ParameterError(f"autoreset_mode DISABLED: sub-env(s) {np.nonzero(pending)[0].tolist()} ended; "
                                 "reset them with reset(options={'reset_mask': mask}) before stepping")
        carved: dict[int, np.ndarray] = {}
        if any_pending:  # NEXT_STEP: they reset instead of stepping; what the reset needs is taken first
            for i in np.nonzero(pending)[0]:
                i = int(i)
                carved[i] = self._surf.carved[i].copy()
                self._close_cycle(i, "reset")
        info, reward, terminated = self._step_all(acts, pending if any_pending else None)
        self._steps += 1
        truncated = self._steps >= self._max_steps
        if any_pending:
            reward[pending] = 0.0
            terminated[pending] = False
            truncated[pending] = False
        ended = terminated | truncated
        for i in np.nonzero(terminated)[0]:
            self._close_cycle(int(i), "stall" if self._stall[i] >= self.cfg.stall_patience else "exit")
        if any_pending:
            request = parse_reset_options(None, self.cfg)
            for i, heights in carved.items():
                self._reset_env(i, request, heights)
            info = self._mask_info(info, ~pending, pending)
        else:
            masks = np.ones((len(STEP_INFO_KEYS), n), dtype=bool)  # one allocation, a row per key
            for key, mask in zip(STEP_INFO_KEYS, masks, strict=True):
                info["_" + key] = mask
        obs = self._observation()
        if mode is AutoresetMode.SAME_STEP and ended.any():
            info = self._same_step_reset(info, obs, ended)
            self._prev_done = np.zeros(n, dtype=bool)
        else:
            self._prev_done = ended
        return obs, reward, terminated, truncated, info

    def _motion_constants(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per axis (x, z, blade angle) as (3, 1) columns: the command scale, the rate limit per step and the
        workspace limits (made once per configuration)."""
        cfg = self.cfg
        if self._motion[0] is not cfg:
            ld = cfg.loader
            (x0, x1), (z0, z1), (a0, a1) = cfg.x_limits, cfg.z_limits, cfg.blade_angle_limits
            dv, dw = cfg.speed_step, cfg.tilt_rate_step
            cols = [np.array(v, dtype=float).reshape(3, 1) for v in ((ld.max_speed, ld.max_speed, ld.max_tilt_rate),
                                                                     (dv, dv, dw), (x0, z0, a0), (x1, z1, a1))]
            self._motion = (cfg, tuple(cols))
        return self._motion[1]

    def _close_cycle(self, i: int, reason: str) -> None:
        if self._records is not None:
            self._records.close(i, int(self._steps[i]), reason, self._surf.carved[i],
                                energy_soil=float(self._e_soil[i]), energy_payload=float(self._e_pay[i]))

    def _step_all(self, a: np.ndarray, pending: np.ndarray | None):
        """Step every sub-env (as BucketLoadingEnv.step, row-wise). Rows in ``pending`` are stepped too but
        reset afterwards (their step draws no noise). Returns the step info (fresh arrays, every
        :data:`STEP_INFO_KEYS` key), the rewards and the terminations."""
        cfg = self.cfg
        ld = cfg.loader
        dt = cfg.dt
        # the three axes at once, as (3, n) rows (the same operations per element; clip as maximum, minimum)
        a = np.array(a.T, order="C")
        np.copyto(a, 0.0, where=np.isnan(a))
        np.maximum(a, -1.0, out=a)
        np.minimum(a, 1.0, out=a)
        scale, rate_step, low, high = self._motion_constants()
        pos = np.array((self._x, self._z, self._th))  # np.stack's values without its Python-level cost
        vel = np.array((self._vx, self._vz, self._om))
        change = np.multiply(a, scale, out=a)
        change -= vel
        np.maximum(change, -rate_step, out=change)
        np.minimum(change, rate_step, out=change)
        vel += change  # rate-limited velocity command
        new = vel * dt
        new += pos
        np.maximum(new, low, out=new)
        np.minimum(new, high, out=new)
        vel = np.subtract(new, pos, out=vel)
        vel /= dt
        x, z, th = pos
        xn, zn, thn = new
        vx, vz, om = vel
        fill0 = self._fill.copy()
        spilled0 = self._spilled.copy()
        removed0 = self._removed.copy()
        kept0 = self._kept.copy()
        payload = cfg.payload
        rows = self._rows
        undo = self._carve(None, x, z, xn, zn)
        fill = self._fill.copy()
        depth, rho, alpha, lt, h_surf = self._surf.contact(None, xn, zn, thn, cfg.slope_window,
                                                           cfg.bucket.floor_length)
        f_t, f_n, flags, beta = self._forces(rows, depth, rho, alpha, lt, fill)
        if payload is not None:  # "fee-payload": the kept soil's weight and inertia, in and out of soil
            kept = kept_volume(self._removed, cfg.bucket.capacity, payload, 0.0,
                               np.where(depth > 0.0, thn, self._exit_angle) if payload.curl_gain else 0.0)
            acc = np.column_stack([(vx - self._vx) / dt, (vz - self._vz) / dt])
            d_t, d_n = carried_forces(depth, alpha - rho, self._gamma * GRAVITY * kept, acc, cfg.model_options)
            f_t, f_n = f_t + d_t, f_n + d_n
            if cfg.force_model == "fee-learned":  # the learned correction at the step's realised speed
                d_t, d_n = self._learned_rows(rows, depth, rho, alpha, thn, fill, kept, np.hypot(xn - x, zn - z) / dt)
                f_t, f_n = f_t + d_t, f_n + d_n
        self._k += 1
        j = self._k % NOISE_CHUNK
        redraw = j == 0 if pending is None else (j == 0) & ~pending
        for i in np.nonzero(redraw)[0]:
            self._noise_n[i], self._noise_u[i] = draw_noise_chunk(self._rngs[i])
        truth_on = cfg.truth.active
        if truth_on:
            dist = np.hypot(xn - x, zn - z)
            f_t, f_n = self._truth(slice(None), rows, f_t, f_n, depth, dist / dt, dist, j, True)
        stalled = (f_t > ld.max_push_force) | (f_n > ld.max_lift_force)
        if stalled.any():
            s = np.nonzero(stalled)[0]
            self._surf.undo(*undo, s)
            fill[s] = fill0[s]
            self._fill[s] = fill0[s]
            self._spilled[s] = spilled0[s]
            self._removed[s] = removed0[s]
            xn[s], zn[s], thn[s] = x[s], z[s], th[s]
            vx[s] = vz[s] = om[s] = 0.0
            d2, rho2, al2, lt2, h2 = self._surf.contact(s, x[s], z[s], th[s], cfg.slope_window,
                                                        cfg.bucket.floor_length)
            h_surf[s] = h2
            ft2, fn2, fl2, beta[s] = self._forces(s, d2, rho2, al2, lt2, fill0[s])
            if payload is not None:  # held: weight only
                d_t, d_n = carried_forces(d2, al2 - rho2, self._gamma[s] * GRAVITY * kept0[s], None,
                                          cfg.model_options)
                ft2, fn2 = ft2 + d_t, fn2 + d_n
                if cfg.force_model == "fee-learned":  # at rest
                    d_t, d_n = self._learned_rows(s, d2, rho2, al2, th[s], fill0[s], kept0[s], 0.0 * d2)
                    ft2, fn2 = ft2 + d_t, fn2 + d_n
            if truth_on:
                ft2, fn2 = self._truth(s, s, ft2, fn2, d2, 0.0, 0.0, None, False)
            depth[s], rho[s], alpha[s], f_t[s], f_n[s], flags[s] = d2, rho2, al2, ft2, fn2, fl2
            self._stall = np.where(stalled, self._stall + 1, 0)
        else:
            self._stall[:] = 0
        self._beta = np.where(depth > 0.0, beta, self._beta)
        if payload is not None and payload.curl_gain:
            self._exit_angle = np.where(depth > 0.0, thn, self._exit_angle)
        carved = fill
        if payload is not None:  # the fill is the payload's kept soil (obs, info, reward, cycle end, records)
            kept = kept_volume(self._removed, cfg.bucket.capacity, payload, 0.0, self._exit_angle)
            fill0, fill = kept0, kept
        self._kept = fill.copy()
        # energy (the shared bookkeeping)
        e_soil, e_pay = step_work(f_t, f_n, xn - x, zn - z, thn, self._gamma * GRAVITY * fill)
        self._e_soil += e_soil
        self._e_pay += e_pay
        # measurement
        rng_r = cfg.sensor_range
        noise = _pairs(self._noise_n).take(self._noise_base + j)  # self._noise_n[rows, j] as (real, imag)
        self._mt = np.minimum(np.maximum(f_t + cfg.sensor_noise * noise.real, -rng_r), rng_r)  # clip
        self._mn = np.minimum(np.maximum(f_n + cfg.sensor_noise * noise.imag, -rng_r), rng_r)
        self._x, self._z, self._th, self._vx, self._vz, self._om = xn, zn, thn, vx, vz, om
        self._depth, self._rho, self._alpha = depth, rho, alpha
        cap = cfg.bucket.capacity
        terms = reward_terms(cfg.reward_weights, cap, ld.max_push_force, ld.max_lift_force, fill - fill0,
                             e_soil + e_pay, outside_validity(depth, flags), stalled, f_t, f_n)
        # cycle end (the shared rule)
        self._touched, self._entered = cycle_progress(self._touched, self._entered, depth > 0.0, fill,
                                                      cfg.exit_fill_volume)
        done = cycle_done(self._touched, self._entered, zn, zn - h_surf, self._crest, cfg.exit_clearance)
        terminated = done | (self._stall >= cfg.stall_patience)
        if self._records is not None:
            self._records.write_step((xn, zn, thn, self._mt, self._mn, fill, f_t, f_n, flags))
        info = dict(zip(REWARD_TERMS, terms, strict=True))
        # fresh arrays only (the env's state arrays change at the next step)
        info.update(fill_volume=fill, fill_fraction=fill / cap,
                    carved_volume=carved.copy() if payload is None else carved, spilled=self._spilled.copy(),
                    force_tangential=f_t, force_normal=f_n, measured_tangential=self._mt.copy(),
                    measured_normal=self._mn.copy(),
                    energy_soil=self._e_soil.copy(), energy_payload=self._e_pay.copy(), depth=depth.copy(),
                    flags=np.asarray(flags, dtype=int), stalled=stalled, cycle_done=done,
                    cycle=np.zeros(self.num_envs, dtype=int))
        return info, terms.total(), terminated

    def _carve(self, rows: np.ndarray | None, xa, za, xb, zb):
        """Carve the rows' segments (every row for None) and fill their buckets (the rest spills); returns what
        undoes the cut."""
        idx_u, old_u, area = self._surf.carve(rows, xa, za, xb, zb)
        if area is None:
            return idx_u, old_u
        removed = area * self.cfg.bucket.width
        fill = self._fill
        room = np.maximum(0.0, self.cfg.bucket.capacity - fill)
        taken = np.where(removed <= room, removed, room)
        pos = removed > 0.0
        self._removed = np.where(pos, self._removed + removed, self._removed)
        self._fill = np.where(pos, fill + taken, fill)
        self._spilled = np.where(pos, self._spilled + (removed - taken), self._spilled)
        return idx_u, old_u

    # ------------------------------------------------------------------ observation
    def _observation(self) -> np.ndarray:
        cfg = self.cfg
        look = cfg.lookahead
        # built as float32 rows (one per column, along the sub-envs), clipped to the float32 bounds there (the same
        # values as clipping in float64 and rounding after: rounding is monotone and the bounds are float32
        # numbers), then transposed in one copy
        rows = np.empty((12 + len(look), self.num_envs), dtype=np.float32)
        np.concatenate((self._x, self._z, self._th, self._vx, self._vz, self._om, self._depth, self._rho, self._alpha,
                        self._kept / cfg.bucket.capacity, self._mt * 1e-3, self._mn * 1e-3), out=rows[:12].reshape(-1),
                       casting="same_kind")
        if look:  # the look-ahead points as rows (k, n): every array operation runs along the sub-envs
            if self._look_col[0] is not look:
                self._look_col = (look, np.array(look, dtype=float).reshape(-1, 1))
            ahead = self._look_col[1] + self._x
            h = self._surf.carved_height(ahead)
            h -= self._z
            rows[12:] = h
        np.maximum(rows, self._low32[:, None], out=rows)  # clip
        np.minimum(rows, self._high32[:, None], out=rows)
        return rows.T.copy()


def _pairs(noise: np.ndarray) -> np.ndarray:
    """The ``(n, NOISE_CHUNK, 2)`` draws as a flat view of ``(first, second)`` pairs (complex numbers): one gather
    of row ``i``'s pair ``j`` at ``i * NOISE_CHUNK + j`` instead of a 2-D fancy index."""
    return noise.view(np.complex128).reshape(-1)


def _signature() -> inspect.Signature:
    """``__init__``'s signature: ``num_envs``, ``max_episode_steps``, ``render_mode`` and the settings of
    :class:`~wheelloader.envs.config.EnvConfig` (keyword-only, typed, with their defaults)."""
    own = inspect.signature(BucketLoadingVectorEnv.__init__.__wrapped__).parameters
    head = [p for name, p in own.items() if name != "settings"]
    return inspect.Signature([*head, *settings_parameters()])


BucketLoadingVectorEnv.__init__.__signature__ = _signature()
