"""RLlib by env id and by class: an env runner samples the batched env built through
``gym_env_vectorize_mode="vector_entry_point"`` (fast smoke tests, in this process); a PPO with 2 remote
env runners on the env by id trains one iteration (slow: starting Ray and the runners takes about a
minute here). The env in a fresh interpreter by its module-qualified id is tested without Ray.

Needs the optional ``rllib`` extra (``pip install torch==2.13.0 && pip install -e ".[rllib]"``); skipped
without it unless ``WHEELLOADER_REQUIRE_RAY=1`` (then a missing install fails).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

if os.environ.get("WHEELLOADER_REQUIRE_RAY") == "1":
    import ray  # noqa: F401
    import torch  # noqa: F401
    from ray.rllib.algorithms.ppo import PPOConfig
else:
    _reason = 'install the RLlib extra: pip install torch==2.13.0 && pip install -e ".[rllib]"'
    pytest.importorskip("torch", reason=_reason)
    pytest.importorskip("ray.rllib", reason=_reason)
    from ray.rllib.algorithms.ppo import PPOConfig

from wheelloader.envs import BucketLoadingEnv, BucketLoadingVectorEnv

pytestmark = pytest.mark.ray

ENV_ID = "wheelloader.envs:wheelloader/BucketLoading-v0"


def _sample(env, mode: str, steps: int = 64) -> tuple[object, int]:
    """Build a local env runner (no Ray actors) for ``env`` and sample ``steps`` env-steps."""
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    config = (PPOConfig().environment(env, env_config={"soil": "random", "sensor_noise": 0.0})
              .env_runners(num_env_runners=0, num_envs_per_env_runner=4, gym_env_vectorize_mode=mode)
              .debugging(seed=0))
    runner = SingleAgentEnvRunner(config=config)
    try:
        episodes = runner.sample(num_timesteps=steps)
        return runner.env.unwrapped, sum(len(e) for e in episodes)
    finally:
        runner.stop()


def test_env_runner_samples_the_batched_env_by_id():
    env, steps = _sample(ENV_ID, "vector_entry_point")
    assert isinstance(env, BucketLoadingVectorEnv) and env.num_envs == 4
    assert env.cfg.sensor_noise == 0.0 and env.max_episode_steps == 600  # env_config and the registered limit
    assert steps >= 64


def test_env_runner_builds_the_env_classes_from_env_config():
    """RLlib calls a class with its env_config (an EnvContext) as the first positional argument."""
    env, steps = _sample(BucketLoadingEnv, "sync")
    assert [type(e.unwrapped) for e in env.envs] == [BucketLoadingEnv] * 4 and steps >= 64
    assert all(e.unwrapped.max_episode_steps == 600 for e in env.envs)
    env, steps = _sample(BucketLoadingVectorEnv, "vector_entry_point")
    assert isinstance(env, BucketLoadingVectorEnv) and env.num_envs == 4 and steps >= 64


def test_env_context_and_keywords_merge():
    from ray.rllib.env.env_context import EnvContext

    ctx = EnvContext({"soil": "sand", "sensor_noise": 0.0}, worker_index=1, num_workers=2)
    env = BucketLoadingEnv(ctx, render_mode="rgb_array")
    assert env.render_mode == "rgb_array" and env.cfg.sensor_noise == 0.0
    obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs))


def test_module_qualified_id_in_a_fresh_interpreter():
    """Gymnasium imports ``wheelloader.envs`` itself for the ``module:id`` form (what RLlib's workers do)."""
    code = ("import sys, gymnasium as gym\n"
            f"env = gym.make({ENV_ID!r}, soil='sand')\n"
            "obs, _ = env.reset(seed=0)\n"
            f"vec = gym.make_vec({ENV_ID!r}, num_envs=3, vectorization_mode='vector_entry_point')\n"
            "print(env.spec.max_episode_steps, obs.shape, type(vec).__name__, vec.num_envs,\n"
            "      'ray' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=os.path.dirname(__file__)).stdout.split()
    assert out == ["600", "(17,)", "BucketLoadingVectorEnv", "3", "False"]


@pytest.mark.slow
def test_ppo_by_id_with_two_env_runners_trains_one_iteration():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    try:
        config = (PPOConfig().environment(ENV_ID, env_config={"soil": "random"})
                  .env_runners(num_env_runners=2, num_envs_per_env_runner=4,
                               gym_env_vectorize_mode="vector_entry_point", rollout_fragment_length=64)
                  .training(train_batch_size_per_learner=512, minibatch_size=128, num_epochs=1)
                  .debugging(seed=0))
        algo = config.build_algo()
        result = algo.train()
        algo.stop()
    finally:
        ray.shutdown()
    assert result["env_runners"]["num_env_steps_sampled"] >= 512
    assert result["fault_tolerance"]["num_env_runners_dropped_lifetime"] == 0


def _train_modules():
    # train/ is on pytest's pythonpath (pyproject.toml): its modules import by name, as the scripts see them
    import policies
    import rollouts

    return policies, rollouts


def test_rllib_policy_loads_a_saved_module_and_runs_the_evaluation_episode(tmp_path):
    """train/policies.py's RLlib policy (what evaluate.py --rllib uses) on a module saved the way a
    checkpoint holds it; deterministic actions, the SB3 baseline's episode metrics."""
    import gymnasium as gym
    from ray.rllib.algorithms.ppo.ppo_catalog import PPOCatalog
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule

    policies, rollouts = _train_modules()
    env = gym.make("wheelloader/BucketLoading-v0")
    module = DefaultPPOTorchRLModule(observation_space=env.observation_space, action_space=env.action_space,
                                     model_config={"fcnet_hiddens": [8]}, catalog_class=PPOCatalog,
                                     inference_only=True)
    where = tmp_path / "checkpoint" / "learner_group" / "learner" / "rl_module" / "default_policy"
    module.save_to_path(str(where))
    policy = policies.load_rllib(tmp_path / "checkpoint", "rllib_test")
    obs, _ = env.reset(seed=0)
    first = policy.act(obs)
    assert first.shape == (3,) and first.dtype == np.float32 and np.all(np.abs(first) <= 1.0)
    np.testing.assert_array_equal(policy.act(obs), first)  # deterministic
    episode = rollouts.run_episode(policy, "gravel", 2000, {"max_episode_steps": 40})
    assert episode["steps"] <= 40 and set(episode) >= {"return", "fill_fraction", "energy_J", "stall"}


@pytest.mark.slow
def test_rllib_training_script_end_to_end(tmp_path):
    """train/rllib_ppo.py with a tiny budget: trains, saves the checkpoint, evaluates it with evaluate.py."""
    import json

    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "train", "rllib_ppo.py")
    cmd = [sys.executable, script, "--total-timesteps", "256", "--num-env-runners", "1", "--num-envs-per-env-runner",
           "2", "--train-batch", "256", "--minibatch-size", "128", "--num-epochs", "1", "--ray-cpus", "2",
           "--eval-soils", "gravel", "--eval-seeds", "2000", "--out", str(tmp_path)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads((tmp_path / "train_summary.json").read_text())
    assert summary["timesteps"] >= 256 and summary["env_id"] == ENV_ID
    report = json.loads((tmp_path / "evaluate" / "evaluation.json").read_text())
    assert "rllib_" + tmp_path.name in report["results"] and "bezier_path1" in report["results"]
