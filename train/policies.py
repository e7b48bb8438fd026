"""Controllers behind one interface for the evaluation: random actions, the paper's fixed Bezier paths,
the MPC planner of ``wheelloader.planner``, trained SB3 models and trained RLlib modules."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from wheelloader.estimator import paper_paths


class Policy:
    """A controller for evaluation: ``reset(seed)`` at the start of an episode, then ``act(obs)``."""

    name = "policy"

    def reset(self, seed: int, env: gym.Env) -> None:  # noqa: B027 - optional hook
        """Start of an episode (``env`` is the evaluation env after its reset)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class RandomPolicy(Policy):
    """Uniform random actions in [-1, 1]^3, seeded per episode."""

    name = "random"

    def __init__(self) -> None:
        self._rng = np.random.default_rng(0)

    def reset(self, seed: int, env: gym.Env) -> None:
        self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, 3).astype(np.float32)


class PathPolicy(Policy):
    """A fixed bucket path (the paper's Fig. 8 paths) tracked with ``wheelloader.envs.scripted.PathTracker``."""

    def __init__(self, index: int) -> None:
        self.index = index
        self.name = f"bezier_path{index + 1}"
        self._tracker = None

    def reset(self, seed: int, env: gym.Env) -> None:
        from wheelloader.envs.config import pile_toe
        from wheelloader.envs.scripted import PathTracker

        cfg = env.unwrapped.cfg
        path = paper_paths(pile_toe(cfg.pile), rate=cfg.control_rate)[self.index]
        self._tracker = PathTracker(path, cfg.loader, cfg.control_rate)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._tracker(obs)


class SB3Policy(Policy):
    """A trained SB3 model, deterministic actions."""

    def __init__(self, model: Any, name: str) -> None:
        self.model = model
        self.name = name

    def act(self, obs: np.ndarray) -> np.ndarray:
        action, _ = self.model.predict(obs, deterministic=True)
        return action


def load_sb3(path: str | Path, name: str | None = None) -> SB3Policy:
    """Load ``model.zip`` (PPO or SAC, read from the run's ``config.json`` or guessed) with SB3's ``load``."""
    from stable_baselines3 import PPO, SAC

    path = Path(path)
    algo = None
    cfg_file = path.parent / "config.json"
    if cfg_file.exists():
        algo = json.loads(cfg_file.read_text()).get("algo")
    if algo is None:
        algo = "sac" if "sac" in path.as_posix().lower() else "ppo"
    cls = {"ppo": PPO, "sac": SAC}[algo.lower()]
    model = cls.load(path, device="cpu")
    return SB3Policy(model, name or f"{algo.lower()}:{path.parent.name}")


class RLlibPolicy(Policy):
    """A trained RLlib RLModule (new API stack), deterministic actions (the mean of its Gaussian), as RLlib's
    own inference does; actions beyond [-1, 1] are clipped by the env, as RLlib's action unsquashing would."""

    def __init__(self, module: Any, name: str) -> None:
        import torch

        self.module = module
        self.name = name
        self._torch = torch
        self._dist = module.get_inference_action_dist_cls()

    def act(self, obs: np.ndarray) -> np.ndarray:
        torch = self._torch
        with torch.no_grad():
            out = self.module.forward_inference({"obs": torch.from_numpy(np.asarray(obs, dtype=np.float32)[None])})
            action = self._dist.from_logits(out["action_dist_inputs"]).to_deterministic().sample()
        return np.clip(action.numpy()[0], -1.0, 1.0).astype(np.float32)


def rllib_module_path(checkpoint: str | Path) -> Path:
    """The default policy's RLModule inside an RLlib algorithm checkpoint (``Algorithm.save_to_path``), or
    ``checkpoint`` itself if it already is a module directory."""
    checkpoint = Path(checkpoint)
    inner = checkpoint / "learner_group" / "learner" / "rl_module" / "default_policy"
    return inner if inner.is_dir() else checkpoint


def load_rllib(checkpoint: str | Path, name: str | None = None) -> RLlibPolicy:
    """Load the RLModule of an RLlib PPO checkpoint (``train/rllib_ppo.py`` writes ``OUT/checkpoint``)."""
    from ray.rllib.core.rl_module.rl_module import RLModule

    module = RLModule.from_checkpoint(str(rllib_module_path(checkpoint).resolve()))
    return RLlibPolicy(module, name or f"rllib:{Path(checkpoint).parent.name}")


def mpc_policy() -> Policy | None:
    """The MPC planner of ``wheelloader.planner`` as a policy, or None if the planner offers none."""
    try:
        import wheelloader.planner as planner
    except ImportError:
        return None
    factory = getattr(planner, "make_env_policy", None)
    if factory is None:
        return None
    return _PlannerPolicy(factory)


class _PlannerPolicy(Policy):
    """Wraps a planner controller ``factory(env) -> callable(obs) -> action``, built at every reset."""

    name = "mpc"

    def __init__(self, factory: Callable) -> None:
        self._factory = factory
        self._ctrl = None

    def reset(self, seed: int, env: gym.Env) -> None:
        self._ctrl = self._factory(env.unwrapped)
        if hasattr(self._ctrl, "reset"):
            self._ctrl.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        ctrl = self._ctrl
        out = ctrl.act(obs) if hasattr(ctrl, "act") else ctrl(obs)
        return np.asarray(out, dtype=np.float32)
