"""NumPy-batched bucket-loading env: many envs stepped in one process (``gym.make_vec``).

Same dynamics, forces, rewards and random streams as
:class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv`: sub-env ``i``
reset with ``seed`` behaves like a single env reset with ``seed + i`` and
given the same actions (autoreset mode ``NEXT_STEP``: the step after a
termination or truncation resets that env, as the single env's ``reset()``
without a seed would). Forces come from the shared vectorised model
:func:`~wheelloader.estimator.soil_forces`, called once per distinct soil;
per-env pile surfaces are rows of 2-D height arrays.

Not supported here (use ``gym.make_vec(..., vectorization_mode="sync")``):
``cycles_per_episode > 1``, cycle logs, twins.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    GRAVITY,
    ContactState,
    Pile,
    SoilParams,
    contact_single,
    soil_forces,
    soil_forces_single,
)
from wheelloader.estimator.errors import ParameterError
from wheelloader.estimator.force_model import FLAG_OUT_OF_SOIL
from wheelloader.estimator.kinematics import blade_length_in_soil

from .bucket_loading import RESET_OPTIONS
from .config import (
    NOISE_CHUNK,
    REWARD_TERMS,
    choose_soil,
    draw_noise_chunk,
    draw_start_pose,
    make_config,
    next_pile,
)
from .truth import as_truth, stone_decay


class BucketLoadingVectorEnv(VectorEnv):
    """Batched :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv` (see its docstring).

    Parameters
    ----------
    num_envs : int
        Number of sub-envs.
    max_episode_steps : int
        Truncation limit per sub-env (``gym.make_vec`` passes the registered one).
    render_mode : str or None
        ``"rgb_array"`` draws sub-env 0.
    **kwargs
        As for the single env (``cycles_per_episode`` must be 1).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 60, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, max_episode_steps: int = 600, render_mode: str | None = None,
                 **kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ParameterError(f"num_envs must be an int >= 1, got {num_envs!r}")
        if isinstance(max_episode_steps, bool) or not isinstance(max_episode_steps, int) or max_episode_steps < 1:
            raise ParameterError(f"max_episode_steps must be an int >= 1, got {max_episode_steps!r}")
        if render_mode not in (None, "rgb_array"):
            raise ParameterError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.cfg = make_config(**kwargs)
        if self.cfg.cycles_per_episode != 1:
            raise ParameterError("the batched vector env supports cycles_per_episode=1 only; use "
                                 "vectorization_mode='sync' for multi-cycle episodes")
        self.num_envs = num_envs
        self.max_episode_steps = max_episode_steps
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(self.cfg.control_rate))}
        self.single_action_space = spaces.Box(-1.0, 1.0, (3,), dtype=np.float32)
        self.action_space = batch_space(self.single_action_space, num_envs)
        low, high = self.cfg.obs_bounds()
        self.single_observation_space = spaces.Box(low, high, dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self._low64, self._high64 = low.astype(np.float64), high.astype(np.float64)
        n, m = num_envs, self.cfg.pile.heights.size
        self._x0, self._sp, self._m = self.cfg.pile.x0, self.cfg.pile.spacing, m
        self._w = np.full(m, self._sp)
        self._w[0] = self._w[-1] = 0.5 * self._sp
        self._h0 = np.empty((n, m))  # start-of-cycle surface (depth)
        self._h = np.empty((n, m))  # carved surface
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._soils: list[SoilParams | None] = [None] * n
        self._groups: list[tuple[SoilParams, np.ndarray | slice]] | None = None
        self._gamma = np.zeros(n)
        z = np.zeros
        self._x, self._z, self._th = z(n), z(n), z(n)
        self._vx, self._vz, self._om = z(n), z(n), z(n)
        self._depth, self._rho, self._alpha = z(n), z(n), z(n)
        self._fill, self._spilled, self._stone = z(n), z(n), z(n)
        self._mt, self._mn = z(n), z(n)
        self._e_soil, self._e_pay = z(n), z(n)
        self._entered = np.zeros(n, dtype=bool)
        self._touched = np.zeros(n, dtype=bool)
        self._crest = np.zeros(n)
        self._stall = np.zeros(n, dtype=np.int64)
        self._k = np.zeros(n, dtype=np.int64)
        self._steps = np.zeros(n, dtype=np.int64)
        self._prev_done = np.zeros(n, dtype=bool)
        self._noise_n = np.zeros((n, NOISE_CHUNK, 2))
        self._noise_u = np.zeros((n, NOISE_CHUNK, 2))
        self._renderer = None
        self._started = False

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        n = self.num_envs
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = [None if s is None else int(s) for s in seed]
            if len(seeds) != n:
                raise ParameterError(f"seed list must have num_envs={n} entries, got {len(seeds)}")
        for i, s in enumerate(seeds):
            if s is not None or self._rngs[i] is None:
                self._rngs[i], _ = seeding.np_random(s)
        opts = dict(options or {})
        unknown = sorted(set(opts) - set(RESET_OPTIONS))
        if unknown:
            raise ParameterError(f"reset options: unknown key(s) {unknown}; expected some of {list(RESET_OPTIONS)}")
        changes: dict[str, Any] = {}
        if "truth" in opts:
            changes["truth"] = as_truth(opts["truth"])
        if "sensor_noise" in opts:
            changes["sensor_noise"] = float(opts["sensor_noise"])
        if changes:
            import dataclasses

            self.cfg = dataclasses.replace(self.cfg, **changes)
        for i in range(n):
            self._reset_env(i, opts)
        self._steps[:] = 0
        self._prev_done[:] = False
        self._started = True
        return self._observation(), {}

    def _reset_env(self, i: int, opts: dict[str, Any]) -> None:
        """Reset sub-env ``i`` exactly as BucketLoadingEnv.reset does (same random draws, same order)."""
        cfg = self.cfg
        rng = self._rngs[i]
        keep = bool(opts.get("keep_pile", cfg.keep_pile))
        relax = opts.get("relax", cfg.relax)
        carved = Pile(self._x0, self._sp, self._h[i]) if keep and self._soils[i] is not None else None
        soil = choose_soil(cfg, self._soils[i], opts.get("soil"), rng)
        if soil is not self._soils[i]:
            self._groups = None
        self._soils[i] = soil
        self._gamma[i] = soil.gamma
        pile = next_pile(cfg, carved, keep, relax, soil)
        self._h0[i] = pile.heights
        self._h[i] = pile.heights
        x, z, th = draw_start_pose(cfg, rng)
        self._x[i], self._z[i], self._th[i] = x, z, th
        self._vx[i] = self._vz[i] = self._om[i] = 0.0
        self._fill[i] = self._spilled[i] = self._stone[i] = 0.0
        self._e_soil[i] = self._e_pay[i] = 0.0
        self._stall[i] = 0
        self._k[i] = 0
        self._steps[i] = 0
        depth, rho, alpha, lt = contact_single(pile, x, z, th, cfg.bucket.floor_length, cfg.slope_window)
        self._depth[i], self._rho[i], self._alpha[i] = depth, rho, alpha
        self._touched[i] = depth > 0.0
        self._entered[i] = depth > 0.0 and cfg.exit_min_fill <= 0.0
        self._crest[i] = float(np.max(pile.heights))
        self._noise_n[i], self._noise_u[i] = draw_noise_chunk(rng)
        f_t, f_n, _, _ = soil_forces_single(soil, depth, rho, alpha, lt, 0.0, cfg.bucket, DEFAULT_OPTIONS)
        r = cfg.sensor_range
        self._mt[i] = min(max(f_t + cfg.sensor_noise * float(self._noise_n[i, 0, 0]), -r), r)
        self._mn[i] = min(max(f_n + cfg.sensor_noise * float(self._noise_n[i, 0, 1]), -r), r)

    # ------------------------------------------------------------------ geometry helpers
    def _interp(self, heights: np.ndarray, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Surface height of ``heights[rows]`` at ``x`` (as Pile.height_at, row-wise; x may be 2-D)."""
        last = self._m - 1
        u = np.clip((x - self._x0) / self._sp, 0.0, last)
        i = u.astype(np.int64)
        f = u - i
        base = rows * self._m if x.ndim == 1 else (rows * self._m)[:, None]
        flat = heights.reshape(-1)
        za = flat[base + i]
        return za + f * (flat[base + np.minimum(i + 1, last)] - za)

    def _contact(self, rows: np.ndarray, x: np.ndarray, z: np.ndarray, th: np.ndarray):
        """(depth, rho, alpha, blade_length, surface height) against the start surfaces (as contact_single)."""
        w = self.cfg.slope_window
        h = self._interp(self._h0, rows, np.stack([x + w, x - w, x], axis=1))
        alpha = np.arctan((h[:, 0] - h[:, 1]) / (2.0 * w))
        vertical = h[:, 2] - z
        depth = np.maximum(vertical, 0.0) * np.cos(alpha)
        rho = alpha - th
        return depth, rho, alpha, blade_length_in_soil(depth, rho, self.cfg.bucket.floor_length), h[:, 2]

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
        """Model forces for the given rows, one soil_forces call per distinct soil."""
        n = rows.size
        # Out of soil the model returns zero forces and FLAG_OUT_OF_SOIL (as soil_forces_single does);
        # only rows in soil go through soil_forces.
        f_t, f_n = np.zeros(n), np.zeros(n)
        flags = np.full(n, FLAG_OUT_OF_SOIL, dtype=np.int64)
        ins = depth > 0.0
        bucket = self.cfg.bucket
        groups = self._soil_groups()
        for soil, members in groups:
            if isinstance(members, slice):
                sel: Any = np.nonzero(ins)[0]
            else:
                sel = np.nonzero(ins & np.isin(rows, members))[0]
            if sel.size == 0:
                continue
            state = ContactState(depth[sel], rho[sel], alpha[sel], lt[sel], fill[sel])
            out = soil_forces(soil, state, bucket, DEFAULT_OPTIONS)
            f_t[sel], f_n[sel], flags[sel] = out.tangential, out.normal, out.flags
        return f_t, f_n, flags

    def _truth(self, g, rows, f_t, f_n, depth, speed, dist, j, new_stones: bool):
        tr = self.cfg.truth
        ins = depth > 0.0
        factor = np.where(ins, 1.0 + tr.compaction * depth, 1.0)
        f_t = np.where(ins, f_t * factor + tr.rate_resistance * self.cfg.bucket.width * depth * speed, f_t)
        f_n = np.where(ins, f_n * factor, f_n)
        stone = self._stone[g]
        if new_stones:
            stone = stone * stone_decay(tr, self.cfg.dt)
            if tr.stone_rate > 0.0:
                u = self._noise_u[rows, j]
                hit = ins & (u[:, 0] < tr.stone_rate * dist)
                stone = np.where(hit, stone - tr.stone_force * np.log1p(-u[:, 1]), stone)
            self._stone[g] = stone
        return f_t + stone, f_n + 0.5 * stone

    # ------------------------------------------------------------------ step
    def step(self, actions: np.ndarray):
        if not self._started:
            raise ParameterError("call reset() before step()")
        n = self.num_envs
        acts = np.asarray(actions, dtype=np.float64).reshape(n, 3)
        acts = np.clip(np.where(np.isnan(acts), 0.0, acts), -1.0, 1.0)
        done = self._prev_done
        reward = np.zeros(n)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        info_terms = {k: np.zeros(n) for k in REWARD_TERMS}
        stalled_all = np.zeros(n, dtype=bool)
        if done.any():
            for i in np.nonzero(done)[0]:
                self._reset_env(int(i), {})
            rows = np.nonzero(~done)[0]
        else:
            rows = np.arange(n)
        if rows.size:
            terms, term, stalled = self._step_rows(rows, acts[rows])
            for key, val in zip(REWARD_TERMS, terms, strict=True):
                info_terms[key][rows] = val
            reward[rows] = terms[0] + terms[1] + terms[2] + terms[3] + terms[4]
            self._steps[rows] += 1
            terminated[rows] = term
            truncated[rows] = self._steps[rows] >= self.max_episode_steps
            stalled_all[rows] = stalled
        self._prev_done = terminated | truncated
        info: dict[str, Any] = dict(info_terms)
        info.update(fill_volume=self._fill.copy(), fill_fraction=self._fill / self.cfg.bucket.capacity,
                    stalled=stalled_all, reset=done.copy())
        return self._observation(), reward, terminated, truncated, info

    def _step_rows(self, r: np.ndarray, a: np.ndarray):
        cfg = self.cfg
        ld = cfg.loader
        g: Any = slice(None) if r.size == self.num_envs else r  # gather/scatter index (a slice is cheaper)
        dt = cfg.dt
        dv, dw = ld.max_acceleration * dt, cfg.max_tilt_acceleration * dt
        x, z, th = self._x[g].copy(), self._z[g].copy(), self._th[g].copy()
        vx = self._vx[g] + np.clip(a[:, 0] * ld.max_speed - self._vx[g], -dv, dv)
        vz = self._vz[g] + np.clip(a[:, 1] * ld.max_speed - self._vz[g], -dv, dv)
        om = self._om[g] + np.clip(a[:, 2] * ld.max_tilt_rate - self._om[g], -dw, dw)
        (x0, x1), (z0, z1), (a0, a1) = cfg.x_limits, cfg.z_limits, cfg.blade_angle_limits
        xn = np.clip(x + vx * dt, x0, x1)
        zn = np.clip(z + vz * dt, z0, z1)
        thn = np.clip(th + om * dt, a0, a1)
        vx, vz, om = (xn - x) / dt, (zn - z) / dt, (thn - th) / dt
        fill0 = self._fill[g].copy()
        spilled0 = self._spilled[g].copy()
        undo = self._carve(r, x, z, xn, zn)
        fill = self._fill[g].copy()
        depth, rho, alpha, lt, h_surf = self._contact(r, xn, zn, thn)
        f_t, f_n, flags = self._forces(r, depth, rho, alpha, lt, fill)
        self._k[g] += 1
        k = self._k[g].copy()
        j = k % NOISE_CHUNK
        for idx in np.nonzero(j == 0)[0]:
            i = int(r[idx])
            self._noise_n[i], self._noise_u[i] = draw_noise_chunk(self._rngs[i])
        dist = np.hypot(xn - x, zn - z)
        truth_on = cfg.truth.active
        if truth_on:
            f_t, f_n = self._truth(g, r, f_t, f_n, depth, dist / dt, dist, j, True)
        stalled = (f_t > ld.max_push_force) | (f_n > ld.max_lift_force)
        if stalled.any():
            s = np.nonzero(stalled)[0]
            idx_u, old_u = undo
            back = np.isin(idx_u // self._m, r[s])
            self._h.reshape(-1)[idx_u[back]] = old_u[back]
            fill[s] = fill0[s]
            self._fill[r[s]] = fill0[s]
            self._spilled[r[s]] = spilled0[s]
            xn[s], zn[s], thn[s] = x[s], z[s], th[s]
            vx[s] = vz[s] = om[s] = 0.0
            d2, rho2, al2, lt2, h2 = self._contact(r[s], x[s], z[s], th[s])
            h_surf[s] = h2
            ft2, fn2, fl2 = self._forces(r[s], d2, rho2, al2, lt2, fill0[s])
            if truth_on:
                ft2, fn2 = self._truth(r[s], r[s], ft2, fn2, d2, 0.0, 0.0, None, False)
            depth[s], rho[s], alpha[s], f_t[s], f_n[s], flags[s] = d2, rho2, al2, ft2, fn2, fl2
            self._stall[g] = np.where(stalled, self._stall[g] + 1, 0)
        else:
            self._stall[g] = 0
        # energy
        ddx, ddz = xn - x, zn - z
        c, s_ = np.cos(thn), np.sin(thn)
        work = f_t * (ddx * c + ddz * s_) + f_n * (ddz * c - ddx * s_)
        e_soil = np.maximum(work, 0.0)
        w_load = self._gamma[g] * GRAVITY * fill
        e_pay = np.maximum(w_load * ddz, 0.0)
        self._e_soil[g] += e_soil
        self._e_pay[g] += e_pay
        # measurement
        rng_r = cfg.sensor_range
        noise = self._noise_n[r, j]
        self._mt[g] = np.clip(f_t + cfg.sensor_noise * noise[:, 0], -rng_r, rng_r)
        self._mn[g] = np.clip(f_n + cfg.sensor_noise * noise[:, 1], -rng_r, rng_r)
        self._x[g], self._z[g], self._th[g], self._vx[g], self._vz[g], self._om[g] = xn, zn, thn, vx, vz, om
        self._depth[g], self._rho[g], self._alpha[g] = depth, rho, alpha
        # reward
        rw = cfg.reward
        cap = cfg.bucket.capacity
        r_fill = rw.fill * (fill - fill0) / cap
        r_energy = -rw.energy * (e_soil + e_pay)
        in_soil = depth > 0.0
        r_valid = np.where(in_soil & ((flags & ~FLAG_OUT_OF_SOIL) != 0), -rw.validity, 0.0)
        r_stall = np.where(stalled, -rw.stall, 0.0)
        soft = rw.force_soft_limit
        excess = (np.maximum(f_t / ld.max_push_force - soft, 0.0) + np.maximum(f_n / ld.max_lift_force - soft, 0.0))
        r_force = -rw.force * excess
        # episode end
        entered = self._entered[g] | (in_soil & (fill >= cfg.exit_min_fill * cap))
        touched = self._touched[g] | in_soil
        self._entered[g] = entered
        self._touched[g] = touched
        clearance = zn - h_surf
        # done: out of the soil after loading (or, with too little loaded, once above the pile's crest)
        out_of_pile = entered | (touched & (zn > self._crest[g] + cfg.exit_clearance))
        cycle_done = out_of_pile & (clearance > cfg.exit_clearance)
        terminated = cycle_done | (self._stall[g] >= cfg.stall_patience)
        return (r_fill, r_energy, r_valid, r_stall, r_force), terminated, stalled

    def _carve(self, r: np.ndarray, xa, za, xb, zb):
        """Batched SurfaceCarver.cut_segment on rows ``r``; returns (flat indices, old heights) of changed nodes."""
        x0, sp, m = self._x0, self._sp, self._m
        lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
        i0 = np.maximum(0, np.ceil((lo - x0) / sp - 1e-12).astype(np.int64))
        i1 = np.minimum(m - 1, np.floor((hi - x0) / sp + 1e-12).astype(np.int64))
        count = i1 - i0 + 1
        width_k = int(count.max()) if count.size else 0
        empty = (np.zeros(0, np.int64), np.zeros(0))
        if width_k <= 0:
            return empty
        cols = i0[:, None] + np.arange(width_k)
        valid = cols <= i1[:, None]
        cols_c = np.minimum(cols, m - 1)
        xi = x0 + cols_c * sp
        dx = xb - xa
        flat = dx == 0.0
        safe = np.where(flat, 1.0, dx)
        zc = za[:, None] + (zb - za)[:, None] * (xi - xa[:, None]) / safe[:, None]
        zc = np.where(flat[:, None], np.minimum(za, zb)[:, None], zc)
        flat_h = self._h.reshape(-1)
        flat_idx = (r * m)[:, None] + cols_c
        old = flat_h[flat_idx]
        cut = valid & (zc < old)
        if not cut.any():
            return empty
        contrib = np.where(cut, self._w[cols_c] * (old - zc), 0.0)
        area = contrib[:, 0].copy()
        for k in range(1, width_k):  # node order, as SurfaceCarver sums
            area += contrib[:, k]
        idx_u, old_u = flat_idx[cut], old[cut]
        flat_h[idx_u] = zc[cut]
        removed = area * self.cfg.bucket.width
        g: Any = slice(None) if r.size == self.num_envs else r
        fill = self._fill[g]
        room = np.maximum(0.0, self.cfg.bucket.capacity - fill)
        taken = np.where(removed <= room, removed, room)
        pos = removed > 0.0
        self._fill[g] = np.where(pos, fill + taken, fill)
        self._spilled[g] = np.where(pos, self._spilled[g] + (removed - taken), self._spilled[g])
        return idx_u, old_u

    # ------------------------------------------------------------------ observation
    def _observation(self) -> np.ndarray:
        cfg = self.cfg
        n = self.num_envs
        look = cfg.lookahead
        obs = np.empty((n, 12 + len(look)))
        obs[:, 0], obs[:, 1], obs[:, 2] = self._x, self._z, self._th
        obs[:, 3], obs[:, 4], obs[:, 5] = self._vx, self._vz, self._om
        obs[:, 6], obs[:, 7], obs[:, 8] = self._depth, self._rho, self._alpha
        obs[:, 9] = self._fill / cfg.bucket.capacity
        obs[:, 10], obs[:, 11] = self._mt * 1e-3, self._mn * 1e-3
        if look:
            ahead = self._x[:, None] + np.asarray(look)[None, :]
            obs[:, 12:] = self._interp(self._h, np.arange(n), ahead) - self._z[:, None]
        np.clip(obs, self._low64, self._high64, out=obs)
        return obs.astype(np.float32)

    # ------------------------------------------------------------------ render
    def render(self):
        if self.render_mode is None:
            return None
        from .rendering import EnvRenderer

        if self._renderer is None:
            self._renderer = EnvRenderer("rgb_array", self.cfg)
        pile0 = Pile(self._x0, self._sp, self._h0[0])
        state = {
            "pile": self.cfg.pile, "start_pile": pile0, "carved": Pile(self._x0, self._sp, self._h[0]),
            "x": float(self._x[0]), "z": float(self._z[0]), "blade_angle": float(self._th[0]),
            "fill": float(self._fill[0]), "capacity": self.cfg.bucket.capacity, "F_T": float(self._mt[0]),
            "F_N": float(self._mn[0]), "floor_length": self.cfg.bucket.floor_length,
            "time": float(self._steps[0]) * self.cfg.dt,
            "limits": (self.cfg.loader.max_push_force, self.cfg.loader.max_lift_force),
        }
        return self._renderer.draw(state)

    def close_extras(self, **kwargs: Any) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state

    @property
    def np_random_generators(self) -> list[np.random.Generator | None]:
        """Per-sub-env generators (sub-env i is seeded with seed + i)."""
        return list(self._rngs)
