"""The training VecEnv and the two training set-ups of the SB3 scripts (domain randomisation, digital twin)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
from common import ENV_ID, SETUPS
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor

import wheelloader.envs  # noqa: F401  (registers the env ids)
from wheelloader.envs.sb3 import make_sb3_vec_env
from wheelloader.estimator import PRESET_NAMES, as_soil, paper_paths

#: ``--vec`` choices: make_sb3_vec_env's backends (``"auto"``: the faster one at the env count) and SB3's DummyVecEnv.
VEC_BACKENDS = ("auto", "batched", "serial", "dummy")


def make_train_env(env_kwargs: dict[str, Any], n_envs: int, seed: int, vec: str = "auto") -> VecEnv:
    """The training VecEnv, wrapped in ``VecMonitor`` (episode returns for the logs), seeded with ``seed`` (sub-env
    ``i`` gets ``seed + i``).

    ``vec``: ``"auto"`` (default: :func:`wheelloader.envs.sb3.make_sb3_vec_env`'s choice, the faster backend at
    ``n_envs`` as ``benchmarks/env_speed.py --sb3`` measured it: serial single envs below ``BATCHED_FROM`` envs,
    the NumPy-batched env from there), ``"batched"`` (:class:`wheelloader.envs.sb3.BatchedVecEnv`), ``"serial"``
    (:class:`wheelloader.envs.sb3.SerialVecEnv`) or ``"dummy"`` (SB3's DummyVecEnv of ``gym.make`` envs). All give
    the same episodes for the same seed and actions, to rounding (the batched env's vectorised tangents may differ
    from the single env's in the last bit).
    """
    if n_envs < 1:
        raise ValueError(f"--n-envs must be >= 1, got {n_envs!r}")
    if vec not in VEC_BACKENDS:
        raise ValueError(f"--vec must be one of {VEC_BACKENDS}, got {vec!r}")
    if vec != "dummy":
        return make_sb3_vec_env(ENV_ID, n_envs, seed, backend=vec, **env_kwargs)
    env = DummyVecEnv([lambda: gym.make(ENV_ID, **env_kwargs) for _ in range(n_envs)])
    env.seed(seed)
    return VecMonitor(env)


def resolve_setup(setup: str, plant_soil: str, seed: int, out: Path | None = None) -> dict[str, Any]:
    """Env keyword arguments and a JSON-able description of a training set-up.

    ``"randomized"``: the plant with the hidden soil drawn uniformly from the
    soil presets at every reset (domain randomisation).
    ``"twin"``: one cycle on the plant (soil ``plant_soil``, seed ``seed``)
    with the reference Bezier path; its logged cycle is calibrated with
    ``wheelloader.estimator.calibrate`` and the policy is trained on the env
    running the calibrated parameters (the digital twin), to be evaluated on
    the plant. The cycle log is saved under ``out`` if given.
    """
    if setup == "randomized":
        return {"env_kwargs": {"soil": "random"},
                "description": {"setup": setup, "soil": "uniform over presets", "presets": list(PRESET_NAMES)}}
    if setup != "twin":
        raise ValueError(f"--setup must be one of {SETUPS}, got {setup!r}")
    calibrate = load_calibrate()
    if calibrate is None:
        raise RuntimeError("set-up 'twin' needs wheelloader.estimator.calibrate, which is not available")
    from wheelloader.envs.config import pile_toe
    from wheelloader.envs.scripted import run_path

    plant = gym.make(ENV_ID, soil=as_soil(plant_soil))
    path = paper_paths(pile_toe(plant.unwrapped.cfg.pile))[0]
    run = run_path(plant, path, seed=seed)
    log = plant.unwrapped.last_cycle_log()
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        log.save(out / "plant_cycle.csv", overwrite=True)
    t0 = time.perf_counter()
    cal = calibrate(log)
    cal_time = time.perf_counter() - t0
    params = cal.params
    truth = as_soil(plant_soil)
    desc = {
        "setup": setup, "plant_soil": plant_soil, "plant_params": truth.to_dict(),
        "calibrated_params": params.to_dict(), "calibration_time_s": cal_time,
        "calibration_success": bool(getattr(cal, "success", True)),
        "plant_cycle": {"path": path.name, "seed": seed, "fill_fraction": run["fill_fraction"],
                        "steps": run["steps"], "stalled": run["stalled"]},
    }
    return {"env_kwargs": {"soil": params}, "description": desc}


def load_calibrate() -> Callable | None:
    """``wheelloader.estimator.calibrate`` if the estimator provides it, else None."""
    try:
        from wheelloader.estimator import calibrate
    except ImportError:
        try:
            from wheelloader.estimator.calibration import calibrate
        except ImportError:
            return None
    return calibrate
