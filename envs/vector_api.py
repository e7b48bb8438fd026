"""Gymnasium's vector API of the batched env, around its physics (:mod:`wheelloader.envs.vector`).

What ``SyncVectorEnv`` of single envs answers, the batched env answers alike (``tests/test_env_vector_api.py``
compares them step by step): seeds per sub-env, ``reset_mask``, the reset and step ``info`` with ``_key``
masks, the autoreset modes' infos (``final_obs`` / ``final_info`` in ``SAME_STEP``), ``get_attr`` /
``set_attr`` / ``call`` of the single env's public attributes and methods per sub-env, and ``render``.
:class:`VectorApi` is a mixin: it works on the state arrays of
:class:`~wheelloader.envs.vector.BucketLoadingVectorEnv`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from wheelloader.estimator import PARAMETER_NAMES, ParameterError, as_soil

from .batched_records import BatchedCycleRecorder
from .bookkeeping import parse_reset_options
from .config import REWARD_TERMS

__all__ = ["PER_ENV_ATTRIBUTES", "PER_ENV_METHODS", "RESET_INFO_KEYS", "STEP_INFO_KEYS", "VectorApi"]

#: Keys of the per-step ``info`` of both envs (the batched env adds a ``_key`` mask to each).
STEP_INFO_KEYS: tuple[str, ...] = REWARD_TERMS + (
    "fill_volume", "fill_fraction", "carved_volume", "spilled", "force_tangential", "force_normal",
    "measured_tangential", "measured_normal", "energy_soil", "energy_payload", "depth", "flags", "stalled",
    "cycle_done", "cycle")
#: Keys of the reset ``info`` of both envs (``soil``: the soil's parameters as a plain dict).
RESET_INFO_KEYS: tuple[str, ...] = ("soil", "cycle")
#: Attributes whose value differs between sub-envs (``get_attr`` / ``call`` give one per sub-env).
PER_ENV_ATTRIBUTES: tuple[str, ...] = ("soil", "np_random", "np_random_seed", "start_pile", "cycle_ends")
#: The single env's methods that ``call`` runs per sub-env.
PER_ENV_METHODS: tuple[str, ...] = ("last_cycle_log", "cycle_logs", "episode_record", "render_state", "render")
_SOURCE = "wheelloader.envs.BucketLoadingVectorEnv"


class VectorApi:
    """The vector API part of :class:`~wheelloader.envs.vector.BucketLoadingVectorEnv` (a mixin)."""

    def _seed_list(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        n = self.num_envs
        if seed is None:
            return [None] * n
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
            return [int(seed) + i for i in range(n)]
        if isinstance(seed, Sequence) and not isinstance(seed, str):
            if len(seed) != n:
                raise ParameterError(f"seed list must have num_envs={n} entries, got {len(seed)}")
            return [None if s is None else int(s) for s in seed]
        raise ParameterError(f"seed must be an int, a list of num_envs ints (or None) or None, got {seed!r}")

    def _check_reset_mask(self, mask: Any) -> np.ndarray:
        n = self.num_envs
        if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.shape != (n,):
            shape = getattr(mask, "shape", None)
            dtype = getattr(mask, "dtype", type(mask).__name__)
            raise ParameterError(f"reset option reset_mask must be a NumPy bool array of shape ({n},), "
                                 f"got {type(mask).__name__} of shape {shape} and dtype {dtype}")
        if not mask.any():
            raise ParameterError("reset option reset_mask must have at least one True entry")
        return mask.copy()

    def _reset_info(self, mask: np.ndarray) -> dict[str, Any]:
        """Reset info of the sub-envs in ``mask``, as SyncVectorEnv gathers the single env's (``soil``: a dict
        of parameter arrays with their masks)."""
        rows = np.nonzero(mask)[0]
        soils = [self._soils[i] for i in rows]
        values = np.zeros((len(PARAMETER_NAMES), self.num_envs))  # a row per parameter
        masks = np.repeat(mask[None, :], len(PARAMETER_NAMES) + 2, axis=0)  # fresh mask rows, one allocation
        if soils:  # one assignment of a (parameter, row) table instead of one per parameter
            values[:, rows] = np.array([[getattr(s, name) for s in soils] for name in PARAMETER_NAMES])
        soil: dict[str, np.ndarray] = {}
        for k, name in enumerate(PARAMETER_NAMES):
            soil[name], soil["_" + name] = values[k], masks[k]
        return {"soil": soil, "_soil": masks[-2], "cycle": np.zeros(self.num_envs, dtype=int), "_cycle": masks[-1]}

    def _mask_info(self, info: dict[str, Any], stepped: np.ndarray, reset: np.ndarray) -> dict[str, Any]:
        """The step info of the sub-envs in ``stepped`` (zeros elsewhere, as SyncVectorEnv leaves them) and the
        reset info of those in ``reset``."""
        out: dict[str, Any] = {}
        if stepped.any():
            idle = np.flatnonzero(~stepped)
            masks = np.repeat(stepped[None, :], len(STEP_INFO_KEYS), axis=0)  # fresh mask rows, one allocation
            for key, mask in zip(STEP_INFO_KEYS, masks, strict=True):
                value = info[key]
                value[idle] = 0
                out[key], out["_" + key] = value, mask
        reset_info = self._reset_info(reset)
        out["soil"], out["_soil"] = reset_info["soil"], reset_info["_soil"]
        out["cycle"], out["_cycle"] = out.get("cycle", reset_info["cycle"]), stepped | reset
        return out

    def _same_step_reset(self, info: dict[str, Any], obs: np.ndarray, ended: np.ndarray) -> dict[str, Any]:
        """SAME_STEP: reset the sub-envs that ended now; their last observation and step info go to
        ``final_obs`` and ``final_info``, their new observation into ``obs`` (in place)."""
        rows = np.nonzero(ended)[0]
        final_obs = np.full(self.num_envs, None, dtype=object)
        for i in rows:
            final_obs[i] = obs[i].copy()
        final_info: dict[str, Any] = {}
        for key in STEP_INFO_KEYS:
            value = info[key].copy()
            value[~ended] = 0
            final_info[key], final_info["_" + key] = value, ended.copy()
        request = parse_reset_options(None, self.cfg)
        for i in rows:
            self._reset_env(int(i), request)
        obs[rows] = self._observation()[rows]
        out = self._mask_info(info, ~ended, ended)
        out["final_obs"], out["_final_obs"] = final_obs, ended.copy()
        out["final_info"], out["_final_info"] = final_info, ended.copy()
        return out

    # ------------------------------------------------------------------ render
    def render(self) -> tuple[np.ndarray, ...] | None:
        """One RGB frame per sub-env (``render_mode="rgb_array"``), as Gymnasium's vector API returns them."""
        if self.render_mode is None:
            return None
        return tuple(self._render_env(i) for i in range(self.num_envs))

    def _render_env(self, i: int) -> np.ndarray:
        from .rendering import EnvRenderer

        if self._renderer is None:
            self._renderer = EnvRenderer("rgb_array", self.cfg)
        return self._renderer.draw(self._render_state(i))

    def _render_state(self, i: int) -> dict[str, Any]:
        """What the renderer draws for sub-env ``i`` (as BucketLoadingEnv.render_state)."""
        return {
            "pile": self.cfg.pile, "start_pile": self._start_piles[i], "carved": self._surf.pile(i),
            "x": float(self._x[i]), "z": float(self._z[i]), "blade_angle": float(self._th[i]),
            "fill": float(self._kept[i]), "capacity": self.cfg.bucket.capacity, "F_T": float(self._mt[i]),
            "F_N": float(self._mn[i]), "floor_length": self.cfg.bucket.floor_length,
            "time": float(self._steps[i]) * self.cfg.dt,
            "limits": (self.cfg.loader.max_push_force, self.cfg.loader.max_lift_force),
        }

    def close_extras(self, **kwargs: Any) -> None:
        # getattr: a constructor that raised (bad input) leaves no renderer, and gymnasium's __del__ still closes
        renderer = getattr(self, "_renderer", None)
        if renderer is not None:
            renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ sub-env attributes and methods
    def _recorder(self) -> BatchedCycleRecorder:
        if self._records is None:
            raise ParameterError("this batched env was built with record_cycles=False: it keeps no cycle records")
        return self._records

    def _per_env(self, name: str, i: int) -> Any:
        if name == "soil":
            return self._soils[i]
        if name == "np_random":
            return self._rngs[i]
        if name == "np_random_seed":
            return self._rng_seeds[i]
        if name == "cycle_ends":
            return self._recorder().histories[i].ends
        return self._start_piles[i]  # start_pile

    def episode_record(self, i: int, index: int = -1, current: bool = False) -> dict[str, np.ndarray]:
        """Sub-env ``i``'s :meth:`BucketLoadingEnv.episode_record` (``call("episode_record", ...)`` asks every
        sub-env)."""
        records = self._recorder()
        if current:
            if not records.is_open(i):
                raise ParameterError("no cycle in progress")
            return records.record(i, int(self._steps[i]))
        if not records.histories[i]:
            raise ParameterError("no finished cycle yet")
        return dict(records.kept(i, index)["record"])

    def last_cycle_log(self, i: int) -> Any:
        """Sub-env ``i``'s :meth:`BucketLoadingEnv.last_cycle_log`."""
        records = self._recorder()
        if not records.histories[i]:
            raise ParameterError("no finished cycle yet: step until termination (or reset) first")
        return records.log(i, -1, self.cfg, _SOURCE)

    def cycle_logs(self, i: int) -> list[Any]:
        """Sub-env ``i``'s :meth:`BucketLoadingEnv.cycle_logs` (oldest first)."""
        records = self._recorder()
        return [records.log(i, k, self.cfg, _SOURCE) for k in range(len(records.histories[i]))]

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """The attribute ``name`` of every sub-env (as ``SyncVectorEnv.get_attr``).

        :data:`PER_ENV_ATTRIBUTES` (``soil``, ``np_random``, ``np_random_seed``, ``start_pile``,
        ``cycle_ends``) differ between sub-envs; any other attribute of the batched env (``cfg``,
        ``render_mode``, ``metadata``, ...) is shared and repeated ``num_envs`` times.
        """
        if name in PER_ENV_ATTRIBUTES:
            return tuple(self._per_env(name, i) for i in range(self.num_envs))
        value = getattr(self, name)
        return tuple(value for _ in range(self.num_envs))

    def set_attr(self, name: str, values: Any) -> None:
        """Set ``name`` in every sub-env: ``values`` is a list of one value per sub-env, or one value for all.

        Per sub-env: ``soil`` (the simulator soil from now on, e.g. calibrated parameters) and
        ``np_random`` (a :class:`numpy.random.Generator`; its ``np_random_seed`` becomes -1, as in
        Gymnasium's envs). Any other existing attribute is shared by the batch, so every sub-env must get
        the same value.
        """
        n = self.num_envs
        if isinstance(values, (list, tuple)):
            if len(values) != n:
                raise ParameterError(f"set_attr({name!r}): expected one value or num_envs={n} values, "
                                     f"got {len(values)}")
            per = list(values)
        else:
            per = [values] * n
        if name == "soil":
            soils = [as_soil(v) for v in per]
            self._soils = soils
            self._gamma[:] = [s.gamma for s in soils]
            self._groups = None
        elif name == "np_random":
            for v in per:
                if not isinstance(v, np.random.Generator):
                    raise ParameterError(f"set_attr('np_random'): expected numpy.random.Generator, "
                                         f"got {type(v).__name__}")
            self._rngs = per
            self._rng_seeds = [-1] * n
        elif name in PER_ENV_ATTRIBUTES or not hasattr(self, name):
            raise ParameterError(f"set_attr: {name!r} cannot be set on the batched env")
        else:
            if any(v is not per[0] and v != per[0] for v in per[1:]):
                raise ParameterError(f"set_attr({name!r}): the attribute is shared by every sub-env of the batched "
                                     "env; give one value")
            setattr(self, name, per[0])

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call ``name`` in every sub-env (as ``SyncVectorEnv.call``); results one per sub-env.

        The single env's methods in :data:`PER_ENV_METHODS` (``last_cycle_log``, ``cycle_logs``,
        ``episode_record``, ``render_state``, ``render``) run per sub-env with the arguments given; a
        per-sub-env attribute (:meth:`get_attr`) is returned as is; another method of the batched env acts on
        the whole batch, so it is called once and its result repeated; a non-callable attribute is returned
        like :meth:`get_attr`. ``make_twin`` needs the single env (``vectorization_mode="sync"``).
        """
        n = self.num_envs
        if name == "render":
            if self.render_mode is None:
                return tuple(None for _ in range(n))
            return tuple(self._render_env(i) for i in range(n))
        if name == "render_state":
            return tuple(self._render_state(i) for i in range(n))
        if name in ("last_cycle_log", "cycle_logs", "episode_record"):
            method = getattr(self, name)
            return tuple(method(i, *args, **kwargs) for i in range(n))
        if name == "make_twin":
            raise ParameterError("make_twin needs the single env: build the vector env with "
                                 "gym.make_vec(..., vectorization_mode='sync') or make a twin of a single env")
        if name in PER_ENV_ATTRIBUTES:
            return self.get_attr(name)
        attr = getattr(self, name)
        result = attr(*args, **kwargs) if callable(attr) else attr
        return tuple(result for _ in range(n))

    @property
    def np_random_seed(self) -> tuple[int | None, ...]:
        """The seed of each sub-env's generator (-1 where it was set directly), as ``SyncVectorEnv`` gives it."""
        return tuple(self._rng_seeds)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state

    @property
    def np_random_generators(self) -> list[np.random.Generator | None]:
        """Per-sub-env generators (sub-env i is seeded with seed + i)."""
        return list(self._rngs)


