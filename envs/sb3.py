"""Stable-Baselines3 adapter of the batched bucket-loading env (optional: needs stable-baselines3).

``import wheelloader.envs.sb3`` needs the ``rl`` extra
(``pip install torch==2.13.0 && pip install "wheelloader[rl]"``); nothing else
in :mod:`wheelloader` imports it.

* :class:`BatchedVecEnv`: SB3's :class:`~stable_baselines3.common.vec_env.VecEnv`
  over :class:`~wheelloader.envs.vector.BucketLoadingVectorEnv` (one process,
  NumPy-batched), through the vector env's public API only: ``reset`` with
  ``reset_mask``, ``get_attr``/``set_attr``/``call`` and ``render``;
* :class:`SerialVecEnv`: SB3's ``DummyVecEnv`` of single envs without its per-step deep copy of the infos
  (the single env returns fresh info dicts and observations every step, so nothing needs copying);
* :func:`make_sb3_vec_env`: the adapter, seeded and wrapped in ``VecMonitor``
  (episode statistics, so that ``evaluate_policy`` needs no warning).

Examples
--------
>>> from stable_baselines3 import PPO                                      # doctest: +SKIP
>>> from wheelloader.envs.sb3 import make_sb3_vec_env
>>> env = make_sb3_vec_env("wheelloader/BucketLoading-v0", n_envs=16, seed=0, soil="random")
>>> model = PPO("MlpPolicy", env).learn(10_000)
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv

from wheelloader.estimator import ParameterError
from wheelloader.estimator.checks import check_choice, check_int

try:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor
except ImportError as exc:  # pragma: no cover - depends on the installation
    raise ImportError('wheelloader.envs.sb3 needs stable-baselines3: pip install torch==2.13.0 && '
                      'pip install "wheelloader[rl]"', name=exc.name) from exc

import wheelloader.envs  # noqa: F401,E402  (registers the env ids)

__all__ = ["BATCHED_FROM", "BatchedVecEnv", "SerialVecEnv", "make_sb3_vec_env"]


class BatchedVecEnv(VecEnv):
    """SB3 ``VecEnv`` over the NumPy-batched bucket-loading vector env.

    The Gymnasium vector env auto-resets in ``NEXT_STEP`` mode (the step after
    an episode end only resets). SB3 expects ``SAME_STEP`` semantics: the
    observation returned with ``done=True`` is already the first one of the
    next episode and the final one is in ``info["terminal_observation"]``. The
    adapter therefore resets finished sub-envs at once with the vector env's
    partial reset (``reset(options={"reset_mask": done})``), which makes the
    same random draws the vector env would make one step later: sub-env ``i``
    still follows the single env seeded with ``seed + i``.

    Parameters
    ----------
    env : str or gymnasium.vector.VectorEnv
        A registered id with a vector entry point (made with ``gym.make_vec``), or a vector env with
        ``AutoresetMode.NEXT_STEP`` and the batched env's ``reset_mask`` support.
    n_envs : int, optional
        Number of sub-envs (with an id; default 1).
    render_mode : str, optional
        ``"rgb_array"`` to render (e.g. for ``VecVideoRecorder``); with an id only.
    **env_kwargs
        Keyword arguments of the env (with an id only).

    Notes
    -----
    ``infos[i]`` holds the single env's step info for sub-env ``i`` (the keys
    whose ``_key`` mask is set), plus ``terminal_observation`` and
    ``TimeLimit.truncated`` at an episode end, as SB3's ``DummyVecEnv`` gives them.
    """

    def __init__(self, env: str | VectorEnv, n_envs: int | None = None, *, render_mode: str | None = None,
                 **env_kwargs: Any) -> None:
        if isinstance(env, str):
            count = 1 if n_envs is None else check_int("n_envs", n_envs)
            env = gym.make_vec(env, num_envs=count, vectorization_mode="vector_entry_point",
                               render_mode=render_mode, **env_kwargs)
        elif n_envs is not None or env_kwargs or render_mode is not None:
            raise ParameterError("n_envs, render_mode and env keyword arguments go with an env id, not with a "
                                 "vector env")
        if not isinstance(env, VectorEnv):
            raise ParameterError(f"env must be an env id or a gymnasium VectorEnv, got {type(env).__name__}")
        mode = env.metadata.get("autoreset_mode")
        if mode != AutoresetMode.NEXT_STEP:
            raise ParameterError(f"the adapter needs a vector env in AutoresetMode.NEXT_STEP, got {mode!r}")
        self.venv = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self.metadata = {**self.metadata, "render_fps": env.metadata.get("render_fps", 30)}
        self._actions: np.ndarray | None = None

    # ------------------------------------------------------------------ stepping
    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else [None if s is None else int(s) for s in seeds]
        options = self._options[0] if self._options else {}
        if any(o != options for o in self._options):
            raise ParameterError("the batched env takes one set of reset options for every sub-env; "
                                 "set_options gave different ones")
        obs, info = self.venv.reset(seed=seed, options=dict(options) or None)
        self.reset_infos = _info_list(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        infos = _info_list(info, self.num_envs)
        if done.any():
            for i in np.nonzero(done)[0]:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            obs, reset_info = self.venv.reset(options={"reset_mask": done.copy()})
            for i, entry in enumerate(_info_list(reset_info, self.num_envs)):
                if done[i]:
                    self.reset_infos[i] = entry
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    # ------------------------------------------------------------------ sub-env access
    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        values = self.venv.get_attr(attr_name)
        return [values[i] for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        chosen = list(self._get_indices(indices))
        if len(chosen) == self.num_envs:
            self.venv.set_attr(attr_name, value)
            return
        values = list(self.venv.get_attr(attr_name))
        for i in chosen:
            values[i] = value
        self.venv.set_attr(attr_name, values)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any) -> list[Any]:
        results = self.venv.call(method_name, *method_args, **method_kwargs)
        return [results[i] for i in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        if self.render_mode != "rgb_array":
            return [None for _ in range(self.num_envs)]
        return list(self.venv.render())

    def _get_indices(self, indices: Any) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return [int(i) for i in indices]


class SerialVecEnv(DummyVecEnv):
    """SB3's ``DummyVecEnv`` of single envs, stepped without its deep copy of the infos.

    ``DummyVecEnv.step_wait`` keeps one info dict per env between steps and returns a deep copy of them (about
    a third of the time of a step of this env). The single env builds a new info dict, observation and
    reset info at every step and reset, so this class hands them over as they are: the same observations,
    rewards, dones and infos (``TimeLimit.truncated``, ``terminal_observation``) in the same order as
    ``DummyVecEnv`` (``tests/test_train.py`` steps both side by side). Everything else is ``DummyVecEnv``'s.
    """

    def step_wait(self):
        obs_buf = self.buf_obs[None]
        rewards, dones = self.buf_rews, self.buf_dones
        infos = []
        for i, (env, action) in enumerate(zip(self.envs, self.actions, strict=True)):
            obs, rewards[i], terminated, truncated, info = env.step(action)
            done = terminated or truncated
            dones[i] = done
            info["TimeLimit.truncated"] = truncated and not terminated
            if done:
                info["terminal_observation"] = obs
                obs, self.reset_infos[i] = env.reset()
            obs_buf[i] = obs
            infos.append(info)
        self.buf_infos = infos
        return obs_buf.copy(), rewards.copy(), dones.copy(), list(infos)


def _info_list(info: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's vector info (arrays with ``_key`` masks; a nested dict for a dict-valued key, such as
    ``soil``) as one dict per sub-env."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, values in info.items():
        if key.startswith("_"):
            continue
        mask = info.get("_" + key)
        nested = _info_list(values, n) if isinstance(values, dict) else None
        for i in range(n):
            if mask is None or mask[i]:
                value = nested[i] if nested is not None else values[i]
                out[i][key] = value.item() if isinstance(value, np.generic) else value
    return out


#: From this many envs on, ``make_sb3_vec_env(backend="auto")`` uses the batched adapter; below it
#: :class:`SerialVecEnv` of single envs, which is faster there (the crossover measured by
#: ``benchmarks/env_speed.py --sb3``, docs/results/env_speed).
BATCHED_FROM = 48


def make_sb3_vec_env(env_id: str = "wheelloader/BucketLoading-v0", n_envs: int = 1, seed: int | None = None, *,
                     backend: str = "auto", monitor: bool = True, render_mode: str | None = None,
                     **env_kwargs: Any) -> VecEnv:
    """The env as an SB3 ``VecEnv``, seeded, in ``VecMonitor``.

    Parameters
    ----------
    env_id : str
        A registered id (with a vector entry point for the batched backend).
    n_envs : int
        Number of sub-envs.
    seed : int, optional
        Sub-env ``i`` is seeded with ``seed + i`` at the first reset.
    backend : {"auto", "batched", "serial", "dummy"}
        ``"batched"``: :class:`BatchedVecEnv` over the NumPy-batched env; ``"serial"``: :class:`SerialVecEnv`
        of single envs; ``"dummy"``: SB3's ``DummyVecEnv`` of single envs; ``"auto"`` (default): batched from
        :data:`BATCHED_FROM` envs on, else serial. All give the same episodes for the same seed and actions
        (same-step auto-reset, terminal observations, the time-limit flag; ``tests/test_train.py``).
    monitor : bool
        Wrap in ``VecMonitor`` (episode returns and lengths in ``info["episode"]``; default True).
    render_mode : str, optional
        ``"rgb_array"`` for ``VecVideoRecorder``.
    **env_kwargs
        Keyword arguments of the env.
    """
    backend = check_choice("backend", backend, ("auto", "batched", "serial", "dummy"))
    count = check_int("n_envs", n_envs)
    if backend == "auto":
        backend = "batched" if count >= BATCHED_FROM else "serial"
    if backend == "batched":
        env: VecEnv = BatchedVecEnv(env_id, count, render_mode=render_mode, **env_kwargs)
    else:
        kind = SerialVecEnv if backend == "serial" else DummyVecEnv
        env = kind([functools.partial(gym.make, env_id, render_mode=render_mode, **env_kwargs)] * count)
    if seed is not None:
        env.seed(seed)
    return VecMonitor(env) if monitor else env
