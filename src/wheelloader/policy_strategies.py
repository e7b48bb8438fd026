"""Strategies of the adaptation loop that a trained policy drives (baseline (e) of :mod:`wheelloader.adaptation`).

* :class:`PolicyStrategy`: the policy acts on the env's observations as the cycle runs (a controller: only a plant
  that accepts one, the FEE env with ``keep_env``);
* :class:`PolicyPath`: the path the policy's bucket takes in the FEE env of the nominal soil on each cycle's pile,
  dug in any plant (the MPM continuum, the DEM).
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import numpy as np

from wheelloader.adaptation import LOOP_ENV_KWARGS, NOMINAL_SOIL, Strategy, finish_cycle
from wheelloader.estimator import Pile, SoilParams, preset
from wheelloader.planner import PlanOutcome

__all__ = ["PolicyPath", "PolicyStrategy"]


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
    model world); no calibration."""

    name = "rl_path"

    def __init__(self, policy: Any, nominal: SoilParams | None = None, env_seed: int = 0) -> None:
        super().__init__(nominal or preset(NOMINAL_SOIL))
        self.policy = policy
        self.env_seed = env_seed

    def plan(self, pile: Pile) -> PlanOutcome:
        from wheelloader.envs import BucketLoadingEnv
        from wheelloader.envs.config import STEPS_PER_CYCLE

        start = time.perf_counter()
        # truncated where the registered env (the policy's training env) truncates: a policy that never ends
        # its cycle on a carved pile would otherwise roll out for ever
        env = BucketLoadingEnv(soil=self.params, pile=pile, sensor_noise=0.0, max_episode_steps=STEPS_PER_CYCLE,
                               **LOOP_ENV_KWARGS)
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
