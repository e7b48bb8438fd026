"""The FEE env as a reference plant: the model's own world behind the :class:`~wheelloader.references.Plant`
interface, so that the plant loop (:func:`wheelloader.plant_loop.run_plant_loop`) runs on it exactly as on
the MPM continuum (a fast check of the loop, and the model-world figure beside the independent one)."""

from __future__ import annotations

from typing import Any

from wheelloader.adaptation import LOOP_ENV_KWARGS, finish_cycle
from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.scripted import run_path
from wheelloader.estimator import BucketPath, CycleLog, Pile, SoilParams


class FEEEnvPlant:
    """Digs a path in a :class:`~wheelloader.envs.BucketLoadingEnv` with a path tracker.

    Parameters
    ----------
    **env_kwargs
        Keyword arguments of the env besides ``soil`` and ``pile`` (e.g. ``sensor_noise``, ``truth``,
        ``exit_min_fill``), on top of the adaptation loop's env settings
        (:data:`wheelloader.adaptation.LOOP_ENV_KWARGS`: the carved pile relaxes, and a cycle ends when the tip
        leaves the soil only once the bucket holds ``LOOP_EXIT_MIN_FILL`` of its capacity, so that a plan that
        crosses a carved step in the air is dug in full). The tracked trajectory, not the planned one, is what
        the log records.
    """

    name = "fee-env"

    def __init__(self, **env_kwargs: Any) -> None:
        for key in ("soil", "pile"):
            if key in env_kwargs:
                raise TypeError(f"FEEEnvPlant: {key!r} is an argument of dig(), not of the plant")
        self.env_kwargs = {**LOOP_ENV_KWARGS, **env_kwargs}

    def dig(self, path: BucketPath, pile: Pile, soil: SoilParams | str, *, seed: int = 0) -> CycleLog:
        """Dig ``path`` into ``pile`` of ``soil``; the log's ``pile_after`` is the carved surface."""
        start = (float(path.x[0]), float(path.z[0]), float(path.blade_angle[0]))
        env = BucketLoadingEnv(soil=soil, pile=pile, start_pose=start, start_noise=(0.0, 0.0, 0.0),
                               **self.env_kwargs)
        ran = run_path(env, path, seed=seed)
        # a path that ends in the soil (or outlasts the episode) has not finished its cycle: close it
        log = env.unwrapped.last_cycle_log() if ran["terminated"] else finish_cycle(env)
        log.metadata["plant"] = self.name
        return log
