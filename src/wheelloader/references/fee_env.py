"""The FEE env as a reference plant: the model's own world behind the :class:`~wheelloader.references.Plant`
interface, so that the adaptation loop (:func:`wheelloader.loop.run_loop`) runs on it exactly as on the MPM
continuum (a fast check of the loop, and the model-world figure beside the independent one).

Two ways to dig in it:

* ``FEEEnvPlant()``: every cycle in a fresh env that starts at the path's first pose on the given (carved) pile,
  measured like any other plant (work along the path, fill from the log, force filtered);
* ``FEEEnvPlant(keep_env=True)``: one env digs every cycle, as a machine would, from one reset to the next
  (its start pose drawn by the seed, its soil drifting between cycles when its truth says so, the carved pile
  relaxing); it accepts a controller (the MPC, a trained policy) that acts on the env's observations, and it
  measures the cycle itself: the env's fill, energy, stalls and validity-domain steps, the raw (noisy) force.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from wheelloader.adaptation import LOOP_ENV_KWARGS, finish_cycle
from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.scripted import PathTracker, run_path
from wheelloader.estimator import FLAG_OUT_OF_SOIL, BucketPath, CycleLog, Pile, SoilParams, WheelloaderError, preset
from wheelloader.references.filtering import DEFAULT_FILTER

#: The env id the plant makes with ``keep_env`` (its time limit included).
ENV_ID = "wheelloader/BucketLoading-v0"


class FEEEnvPlant:
    """Digs a path (or runs a controller) in a :class:`~wheelloader.envs.BucketLoadingEnv`.

    Parameters
    ----------
    keep_env : bool
        One env for every cycle of a loop (see the module docstring; default False: a fresh env per cycle).
    env : gymnasium.Env, optional
        With ``keep_env``: the env to dig in (made with ``gymnasium.make``; its own soil and pile are used, and it
        is not closed by :meth:`close`). Default: the plant makes one at the first cycle.
    **env_kwargs
        Keyword arguments of the env besides ``soil`` and ``pile`` (e.g. ``sensor_noise``, ``truth``,
        ``exit_min_fill``), on top of the adaptation loop's env settings
        (:data:`wheelloader.adaptation.LOOP_ENV_KWARGS`: the carved pile relaxes, and a cycle ends when the tip
        leaves the soil only once the bucket holds ``LOOP_EXIT_MIN_FILL`` of its capacity, so that a plan that
        crosses a carved step in the air is dug in full). The tracked trajectory, not the planned one, is what
        the log records.
    """

    name = "fee-env"

    def __init__(self, *, keep_env: bool = False, env: Any = None, **env_kwargs: Any) -> None:
        for key in ("soil", "pile"):
            if key in env_kwargs:
                raise TypeError(f"FEEEnvPlant: {key!r} is an argument of dig(), not of the plant")
        if env is not None and env_kwargs:
            raise TypeError(f"FEEEnvPlant: with env given its settings are the env's, got {sorted(env_kwargs)}")
        self.keep_env = bool(keep_env) or env is not None
        self.env_kwargs = {**LOOP_ENV_KWARGS, **env_kwargs}
        #: A controller strategy's controller acts on the kept env's observations (:meth:`dig`).
        self.accepts_controller = self.keep_env
        #: The loop's force filter [s]: none in the kept env (its calibration sees the sensor noise raw).
        self.filter_sigma_s: float | None = None if self.keep_env else DEFAULT_FILTER["sigma_s"]
        self._env = env
        self._owned = env is None
        self._obs: Any = None

    def start_cycle(self, pile: Pile | Mapping[str, Any], soil: SoilParams | str, *, seed: int = 0,
                    first: bool = False) -> Pile | Mapping[str, Any]:
        """The pile the next cycle starts on. With ``keep_env``: the first cycle makes the env (unless given) and
        resets it with ``seed``, a later one resets it keeping the carved pile and the soil; the env's start pile
        is returned. Otherwise ``pile`` as given."""
        if not self.keep_env:
            return pile
        if first:
            if self._owned:
                import gymnasium as gym

                import wheelloader.envs  # noqa: F401  (registers the env ids in this process)

                self.close()
                self._env = gym.make(ENV_ID, soil=soil, pile=pile, **self.env_kwargs)
            self._obs, _ = self._env.reset(seed=seed)
        elif self._env is None:
            raise WheelloaderError("FEEEnvPlant: start the loop's first cycle (first=True) before later ones")
        else:
            self._obs, _ = self._env.reset(options={"keep_pile": True, "soil": "keep"})
        return self._env.unwrapped.start_pile

    def dig(self, path: BucketPath | None, pile: Pile, soil: SoilParams | str, *, seed: int = 0,
            controller: Callable[[np.ndarray], np.ndarray] | None = None) -> CycleLog:
        """Dig ``path`` into ``pile`` of ``soil``; the log's ``pile_after`` is the carved surface.

        With ``keep_env`` the cycle runs in the kept env from the state :meth:`start_cycle` left (``pile``,
        ``soil`` and ``seed`` were given there), tracking ``path`` or, when given, running ``controller``
        (``controller(obs) -> action``); the env's measurements go into ``metadata["measured"]``.
        """
        if self.keep_env:
            return self._dig_kept(path, controller)
        if controller is not None:
            raise WheelloaderError("FEEEnvPlant: a controller needs the kept env (keep_env=True)")
        start = (float(path.x[0]), float(path.z[0]), float(path.blade_angle[0]))
        env = BucketLoadingEnv(soil=soil, pile=pile, start_pose=start, start_noise=(0.0, 0.0, 0.0),
                               **self.env_kwargs)
        ran = run_path(env, path, seed=seed)
        # a path that ends in the soil (or outlasts the episode) has not finished its cycle: close it
        log = env.unwrapped.last_cycle_log() if ran["terminated"] else finish_cycle(env)
        log.metadata["plant"] = self.name
        return log

    def _dig_kept(self, path: BucketPath | None, controller: Callable[[np.ndarray], np.ndarray] | None) -> CycleLog:
        env, obs = self._env, self._obs
        if env is None or obs is None:
            raise WheelloaderError("FEEEnvPlant: call start_cycle before each dig with keep_env")
        base = env.unwrapped
        if controller is None:
            if path is None:
                raise WheelloaderError("FEEEnvPlant: dig needs a path or a controller")
            controller = PathTracker(path, base.cfg.loader, base.cfg.control_rate)
        terminated = truncated = False
        violations = 0
        info: dict[str, Any] = {}
        while not (terminated or truncated):
            obs, _, terminated, truncated, info = env.step(controller(obs))
            if int(info["flags"]) & ~FLAG_OUT_OF_SOIL and info["depth"] > 0.0:
                violations += 1
        self._obs = None
        log = base.last_cycle_log() if terminated else finish_cycle(env)
        log.metadata["plant"] = self.name
        log.metadata["measured"] = {
            "fill_m3": float(info["fill_volume"]), "fill_fraction": float(info["fill_fraction"]),
            "energy_J": float(info["energy_soil"] + info["energy_payload"]), "stalled": bool(info["stalled"]),
            "validity_violations": violations, "end": log.metadata.get("end", "")}
        return log

    def true_soil(self, soil: SoilParams | str) -> SoilParams:
        """The soil the plant digs now: with ``keep_env`` the env's (drifted) soil, else ``soil``."""
        if self.keep_env and self._env is not None:
            return self._env.unwrapped.soil
        return preset(soil) if isinstance(soil, str) else soil

    def close(self) -> None:
        """Close the env the plant made (one given to it is the caller's)."""
        if self._owned and self._env is not None:
            self._env.close()
            self._env = None
