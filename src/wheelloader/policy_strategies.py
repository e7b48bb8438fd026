"""Strategies of the adaptation loop that a trained policy drives (baseline (e) of :mod:`wheelloader.adaptation`).

* :class:`PolicyStrategy`: the policy acts on the env's observations as the cycle runs (a controller: only a plant
  that accepts one, the FEE env with ``keep_env``);
* :class:`PolicyPath`: the path the policy's bucket takes in the FEE env of the nominal soil on each cycle's pile,
  dug in any plant (the MPM continuum, the DEM): an open-loop replay;
* :class:`PolicyClosedLoop`: the policy acts on the plant's own state every control step (the MPM plant builds the
  env's observation from it, :mod:`wheelloader.references.mpm.closed_loop`); its path in the FEE env comes with it
  as the cycle's plan (where the bucket may go, and the saved cycle's key).

The env a policy was trained in (its force model) is the one it is rolled out in: :func:`policy_env_kwargs` reads it
from the ``config.json`` that ``train/ppo.py`` writes beside the ``model.zip``.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.adaptation import LOOP_ENV_KWARGS, NOMINAL_SOIL, Strategy, finish_cycle
from wheelloader.estimator import Pile, SoilParams, preset
from wheelloader.planner import PlanOutcome

__all__ = ["POLICY_STRATEGY_NAMES", "EnvController", "PolicyClosedLoop", "PolicyPath", "PolicyStrategy",
           "policy_env_kwargs", "policy_strategy"]

#: The strategies a trained policy drives (:func:`policy_strategy`).
POLICY_STRATEGY_NAMES: tuple[str, ...] = ("rl", "rl_path", "rl_closed")
#: The env settings a policy's ``config.json`` may set for its rollouts (``train/ppo.py --force-model``).
POLICY_ENV_KEYS: tuple[str, ...] = ("force_model",)


def policy_env_kwargs(model_zip: str | Path) -> dict[str, Any]:
    """The env settings the policy at ``model_zip`` was trained with, from the ``config.json`` beside it
    (``env_kwargs``: its force model), empty where there is none (a policy trained before the file said so: the
    env's defaults, the FEE)."""
    config = Path(model_zip).with_name("config.json")
    if not config.is_file():
        return {}
    kwargs = json.loads(config.read_text()).get("env_kwargs") or {}
    return {k: v for k, v in kwargs.items() if k in POLICY_ENV_KEYS}


def policy_strategy(name: str, rl_policy: str | Path | None) -> Strategy:
    """A policy strategy by name (:data:`POLICY_STRATEGY_NAMES`) with the stable-baselines3 PPO ``.zip`` at
    ``rl_policy``, rolled out in the env it was trained in (:func:`policy_env_kwargs`)."""
    from wheelloader.estimator import WheelloaderError

    if name not in POLICY_STRATEGY_NAMES:
        raise WheelloaderError(f"unknown policy strategy {name!r}; choose from {POLICY_STRATEGY_NAMES}")
    if not rl_policy:
        raise WheelloaderError(f"strategy {name!r} needs a trained policy (rl_policy=PATH of a PPO .zip)")
    from stable_baselines3 import PPO

    policy = PPO.load(rl_policy, device="cpu")
    if name == "rl":
        return PolicyStrategy(policy)
    cls = PolicyPath if name == "rl_path" else PolicyClosedLoop
    return cls(policy, env_kwargs=policy_env_kwargs(rl_policy))


class EnvController:
    """A policy as the controller of a plant that builds the env's observations (``obs -> action``, deterministic),
    with the env settings it acts in (``env_config``: the rollout env's)."""

    name = "policy"

    def __init__(self, policy: Any, env_config: Any) -> None:
        self.policy = policy
        self.env_config = env_config

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        action, _ = self.policy.predict(obs, deterministic=True)
        return action


class PolicyStrategy(Strategy):
    """Baseline (e): a trained policy (e.g. stable-baselines3 PPO) digs every cycle; no calibration."""

    name = "rl"

    def __init__(self, policy: Any, nominal: SoilParams | None = None) -> None:
        super().__init__(nominal or preset(NOMINAL_SOIL))
        self.policy = policy

    def plan(self, pile: Pile) -> PlanOutcome:
        def act(obs: np.ndarray) -> np.ndarray:
            action, _ = self.policy.predict(obs, deterministic=True)
            return action

        return PlanOutcome(None, True, "policy", 0.0, controller=act)


class PolicyPath(Strategy):
    """A trained policy on a plant that digs paths only (the MPM continuum, the DEM): on each cycle's pile the
    policy is rolled out, deterministically, in the FEE env of the nominal soil (the loop's env settings, no
    sensor noise, reset with ``env_seed``), and the path its bucket tip took there is dug in the plant. The
    policy does not see the plant's forces during the cycle (an open-loop replay of what it would do in the
    model world); no calibration. ``env_kwargs``: env settings on top of the loop's (the policy's training
    env's force model, :func:`policy_env_kwargs`)."""

    name = "rl_path"

    def __init__(self, policy: Any, nominal: SoilParams | None = None, env_seed: int = 0,
                 env_kwargs: dict[str, Any] | None = None) -> None:
        super().__init__(nominal or preset(NOMINAL_SOIL))
        self.policy = policy
        self.env_seed = env_seed
        self.env_kwargs = {**LOOP_ENV_KWARGS, **dict(env_kwargs or {})}
        self._config: Any = None

    def plan(self, pile: Pile) -> PlanOutcome:
        from wheelloader.envs import BucketLoadingEnv
        from wheelloader.envs.config import STEPS_PER_CYCLE

        start = time.perf_counter()
        # truncated where the registered env (the policy's training env) truncates: a policy that never ends
        # its cycle on a carved pile would otherwise roll out for ever
        env = BucketLoadingEnv(soil=self.params, pile=pile, sensor_noise=0.0, max_episode_steps=STEPS_PER_CYCLE,
                               **self.env_kwargs)
        self._config = env.cfg
        try:
            obs, _ = env.reset(seed=self.env_seed)
            terminated = truncated = False
            while not (terminated or truncated):
                action, _ = self.policy.predict(obs, deterministic=True)
                obs, _, terminated, truncated, _ = env.step(action)
            log = env.last_cycle_log() if terminated else finish_cycle(env)
        finally:
            env.close()
        path = replace(log.path, name="policy")
        return PlanOutcome(path, True, f"policy rolled out in the FEE env of the nominal soil, {len(path.t)} samples",
                           time.perf_counter() - start)


class PolicyClosedLoop(PolicyPath):
    """A trained policy closed loop in a plant that builds the env's observations from its own state (the MPM
    plant, :mod:`wheelloader.references.mpm.closed_loop`): each cycle's plan is the policy's path in the FEE env
    of the nominal soil (:class:`PolicyPath`; the plant's envelope of where the bucket may go, and the key of the
    saved cycle) and the policy as the controller that digs it, acting on the plant's forces, fill and surface
    every control step; no calibration."""

    name = "rl_closed"

    def plan(self, pile: Pile) -> PlanOutcome:
        outcome = super().plan(pile)
        return replace(outcome, message=outcome.message + "; dug closed loop by the policy",
                       controller=EnvController(self.policy, self._config))
