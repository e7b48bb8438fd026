"""Smoke tests of the packaged SB3 adapter and the training and evaluation scripts in train/ (tiny budgets,
no learning asserted).

The scripts are not a package: they run as subprocesses, and their modules are imported by name, as the
scripts see them (``train/`` is on pytest's ``pythonpath``, pyproject.toml). Skipped without stable-baselines3
and torch, unless ``WHEELLOADER_REQUIRE_RL=1`` (then a missing install fails).
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

if os.environ.get("WHEELLOADER_REQUIRE_RL") == "1":  # CI sets this after installing the rl extra: no silent skip
    import moviepy  # noqa: F401  (in the rl extra, for VecVideoRecorder)
    import stable_baselines3  # noqa: F401
    import torch  # noqa: F401
else:
    pytest.importorskip("stable_baselines3", reason='install: pip install torch==2.13.0 && pip install -e ".[rl]"')
    pytest.importorskip("torch", reason='install: pip install torch==2.13.0 && pip install -e ".[rl]"')

TRAIN = Path(__file__).resolve().parents[1] / "train"


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(TRAIN / script), *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{' '.join(cmd)} failed:\n{proc.stdout}\n{proc.stderr}"
    return proc


@pytest.fixture(scope="module")
def common() -> SimpleNamespace:
    """The train/ modules' public names in one namespace (imported, not executed with runpy)."""
    names: dict = {}
    for module in ("common", "setups", "policies", "rollouts", "curves", "training"):
        names.update({k: v for k, v in vars(importlib.import_module(module)).items() if not k.startswith("_")})
    return SimpleNamespace(**names)


def test_batched_adapter_matches_dummy_vec_env(common):
    """Same seeds and actions: the batched adapter and SB3's DummyVecEnv of single envs agree step by step,
    including same-step auto-reset, terminal observations and the time-limit flag."""
    kwargs = {"soil": "random", "max_episode_steps": 40}
    batched = common.make_train_env(kwargs, 3, 11, "batched")
    dummy = common.make_train_env(kwargs, 3, 11, "dummy")
    rng = np.random.default_rng(0)
    ob, od = batched.reset(), dummy.reset()
    np.testing.assert_allclose(ob, od, atol=1e-5)
    ends = 0
    for _ in range(150):
        act = rng.uniform(-1, 1, (3, 3)).astype(np.float32)
        act[:, 0] = np.abs(act[:, 0])
        ob, rb, db, ib = batched.step(act)
        od, rd, dd, id_ = dummy.step(act)
        np.testing.assert_array_equal(db, dd)
        np.testing.assert_allclose(rb, rd, rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(ob, od, atol=1e-4)
        for i in np.nonzero(db)[0]:
            ends += 1
            np.testing.assert_allclose(ib[i]["terminal_observation"], id_[i]["terminal_observation"], atol=1e-4)
            assert ib[i]["TimeLimit.truncated"] == id_[i]["TimeLimit.truncated"]
            assert ib[i]["episode"]["l"] == id_[i]["episode"]["l"]
    assert ends >= 3
    batched.close()
    dummy.close()


def test_serial_vec_env_is_dummy_vec_env_without_copies():
    """make_sb3_vec_env's serial backend (the default below BATCHED_FROM envs) gives what SB3's DummyVecEnv gives,
    bit for bit: observations, rewards, dones and every info (terminal observation, time-limit flag, episode
    statistics), through time-limit and exit ends; each step's infos are new dicts."""
    from wheelloader.envs.sb3 import BATCHED_FROM, SerialVecEnv, make_sb3_vec_env

    kwargs = {"soil": "random", "max_episode_steps": 30}
    serial = make_sb3_vec_env(n_envs=3, seed=4, **kwargs)
    dummy = make_sb3_vec_env(n_envs=3, seed=4, backend="dummy", **kwargs)
    assert isinstance(serial.venv, SerialVecEnv) and BATCHED_FROM > 3
    np.testing.assert_array_equal(serial.reset(), dummy.reset())
    rng = np.random.default_rng(1)
    ends, previous = 0, None
    for t in range(120):
        act = rng.uniform(-1, 1, (3, 3)).astype(np.float32)
        act[:, 0] = np.abs(act[:, 0])
        act[:, 1] = np.abs(act[:, 1]) if t % 40 >= 20 else act[:, 1]
        out_s, out_d = serial.step(act), dummy.step(act)
        for a, b in zip(out_s[:3], out_d[:3], strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        for info_s, info_d in zip(out_s[3], out_d[3], strict=True):
            assert info_s.keys() == info_d.keys()
            for key, value in info_d.items():
                if key == "episode":  # its "t" is the wall time since the start
                    assert {k: info_s[key][k] for k in "rl"} == {k: value[k] for k in "rl"}
                else:
                    np.testing.assert_array_equal(info_s[key], value, err_msg=key)
        if previous is not None:
            assert all(a is not b for a, b in zip(previous, out_s[3], strict=True))
        previous = out_s[3]
        ends += int(out_s[2].sum())
    assert ends >= 3
    assert serial.reset_infos == dummy.reset_infos
    serial.close()
    dummy.close()


def test_run_episode_metrics(common):
    """A fixed Bezier path fills the bucket on gravel; the random policy is reproducible per seed."""
    ep = common.run_episode(common.PathPolicy(0), "gravel", 3)
    assert ep["fill_fraction"] > 0.5
    assert ep["energy_J"] > 0.0
    assert ep["energy_per_m3_J"] == pytest.approx(ep["energy_J"] / ep["fill_volume_m3"])
    a = common.run_episode(common.RandomPolicy(), "sand", 4)
    b = common.run_episode(common.RandomPolicy(), "sand", 4)
    assert a == b
    s = common.summarize([ep, a])
    assert s["episodes"] == 2 and 0.0 <= s["stall_rate"] <= 1.0


def test_train_vec_default_is_the_faster_backend_at_each_env_count(common):
    """train/'s --vec default "auto" is make_sb3_vec_env's choice: serial single envs below BATCHED_FROM envs, the
    batched env from there (the faster one at each count, benchmarks/env_speed.py --sb3); the others as named."""
    from wheelloader.envs.sb3 import BATCHED_FROM, BatchedVecEnv, SerialVecEnv

    parser = argparse.ArgumentParser()
    common.add_training_args(parser, 64, 2)
    assert parser.parse_args([]).vec == "auto"
    for n, vec, kind in ((2, "auto", SerialVecEnv), (BATCHED_FROM, "auto", BatchedVecEnv),
                         (2, "batched", BatchedVecEnv), (2, "serial", SerialVecEnv)):
        env = common.make_train_env({"max_episode_steps": 20}, n, 0, vec)
        assert type(env.venv) is kind, (n, vec)
        env.close()
    with pytest.raises(ValueError, match="--vec"):
        common.make_train_env({}, 2, 0, "fast")


def test_train_and_evaluate_smoke(tmp_path):
    """PPO and SAC train for a tiny budget, save loadable models, and the evaluation compares them with the
    baselines (JSON, Markdown table, learning-curve PNG)."""
    common_args = ["--no-progress-bar", "--n-envs", "2", "--eval-soils", "gravel", "--eval-seeds", "1000",
                   "--eval-freq", "32", "--checkpoint-freq", "32"]
    _run("ppo.py", "--total-timesteps", "64", "--n-steps", "16", "--batch-size", "16", "--out",
         str(tmp_path / "ppo"), *common_args)
    _run("sac.py", "--total-timesteps", "64", "--learning-starts", "32", "--batch-size", "16", "--out",
         str(tmp_path / "sac"), "--vec", "dummy", *common_args)
    for algo in ("ppo", "sac"):
        out = tmp_path / algo
        assert (out / "model.zip").exists() and (out / "checkpoints").is_dir()
        curve = json.loads((out / "learning_curve.json").read_text())
        assert curve["records"][0]["timesteps"] == 0 and curve["records"][-1]["timesteps"] >= 64
        summary = json.loads((out / "train_summary.json").read_text())
        assert summary["timesteps"] >= 64 and summary["env_steps_per_s"] > 0
        config = json.loads((out / "config.json").read_text())
        assert config["vec_env"] == {"ppo": "SerialVecEnv", "sac": "DummyVecEnv"}[algo]  # --vec auto at 2 envs
    from stable_baselines3 import PPO, SAC

    model = PPO.load(tmp_path / "ppo" / "model.zip", device="cpu")
    action, _ = model.predict(np.zeros(model.observation_space.shape, np.float32), deterministic=True)
    assert action.shape == (3,)
    assert SAC.load(tmp_path / "sac" / "model.zip", device="cpu").action_space.shape == (3,)

    _run("evaluate.py", "--ppo", str(tmp_path / "ppo" / "model.zip"), "--sac", str(tmp_path / "sac" / "model.zip"),
         "--soils", "gravel", "--seeds", "7,8", "--mpc-seeds", "7", "--bezier", "1,2", "--out", str(tmp_path / "eval"))
    report = json.loads((tmp_path / "eval" / "evaluation.json").read_text())
    names = set(report["results"])
    assert {"ppo_randomized", "sac_randomized", "bezier_path1", "bezier_path2", "random"} <= names
    for name, res in report["results"].items():
        for key in ("fill_fraction", "energy_J", "energy_per_m3_J", "stall_rate", "validity_violations",
                    "force_limit_violations"):
            assert key in res["overall"]
        assert res["per_soil"]["gravel"]["episodes"] == (1 if name == "mpc" else 2)
    assert (tmp_path / "eval" / "learning_curve.png").stat().st_size > 0
    table = (tmp_path / "eval" / "evaluation.md").read_text()
    assert "bezier_path1" in table
    if "mpc" in names:  # the planner provides an env policy: one episode (--mpc-seeds), a matched table
        assert report["seeds_by_policy"] == {"mpc": [7]}
        assert "mpc (1 episode)" in table and "On the MPC planner's seeds only" in table


def test_evaluate_seeds_by_policy(common):
    """``seeds_by_policy`` gives one policy (the slow MPC in the full run) fewer seeds than the others."""
    random = common.RandomPolicy()
    fewer = common.RandomPolicy()
    fewer.name = "mpc"
    res = common.evaluate([random, fewer], ["sand"], [1, 2, 3], {"max_episode_steps": 20},
                             seeds_by_policy={"mpc": [2]})
    assert [e["seed"] for e in res["random"]["episodes"]] == [1, 2, 3]
    assert [e["seed"] for e in res["mpc"]["episodes"]] == [2]
    assert res["mpc"]["episodes"][0] == res["random"]["episodes"][1]


def test_mpc_policy_uses_planner_make_env_policy(common, monkeypatch):
    """When ``wheelloader.planner.make_env_policy(env)`` exists, the evaluation wraps its controller
    (``reset()`` at every episode, ``__call__(obs) -> action``); without it the MPC is skipped."""
    import wheelloader.planner as planner

    calls = {"made": 0, "reset": 0, "act": 0}

    class Controller:
        def __init__(self, env) -> None:
            assert hasattr(env, "cfg")
            calls["made"] += 1

        def reset(self) -> None:
            calls["reset"] += 1

        def __call__(self, obs: np.ndarray) -> np.ndarray:
            calls["act"] += 1
            return np.array([0.5, 0.0, 0.0], dtype=np.float32)

    monkeypatch.setattr(planner, "make_env_policy", Controller, raising=False)
    policy = common.mpc_policy()
    assert policy is not None and policy.name == "mpc"
    ep = common.run_episode(policy, "gravel", 1, {"max_episode_steps": 30})
    assert calls["made"] == 1 and calls["reset"] == 1 and calls["act"] == ep["steps"] > 0
    monkeypatch.delattr(planner, "make_env_policy")
    assert common.mpc_policy() is None


def test_packaged_adapter_uses_only_the_public_vector_api():
    """The adapter lives in the package and reaches no private attribute of the batched env."""
    import inspect

    import wheelloader.envs.sb3 as adapter

    source = inspect.getsource(adapter)
    assert "venv._" not in source and "unwrapped._" not in source and "base._" not in source
    from wheelloader.estimator import preset

    env = adapter.make_sb3_vec_env(n_envs=2, seed=3, monitor=False, backend="batched", soil="sand")
    assert isinstance(env, adapter.BatchedVecEnv)
    env.reset()
    assert env.get_attr("soil") == [preset("sand")] * 2
    env.set_attr("soil", "gravel", indices=[1])
    assert env.get_attr("soil") == [preset("sand"), preset("gravel")]
    assert env.env_method("render") == [None, None]  # no render_mode
    env.close()


def test_evaluate_policy_runs_without_warnings():
    """SB3's evaluate_policy on the packaged adapter: no warning (VecMonitor inside), every episode counted."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.evaluation import evaluate_policy

    from wheelloader.envs.sb3 import make_sb3_vec_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make_sb3_vec_env(n_envs=2, seed=0, max_episode_steps=20)
        model = PPO("MlpPolicy", env, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")
        rewards, lengths = evaluate_policy(model, env, n_eval_episodes=4, return_episode_rewards=True)
        assert len(rewards) == 4 and all(0 < n <= 20 for n in lengths)
        env.close()


def test_video_recorder_runs_without_warnings(tmp_path):
    """SB3's VecVideoRecorder on the packaged adapter (render_mode="rgb_array"): no warning, a video written."""
    pytest.importorskip("moviepy", reason='VecVideoRecorder needs moviepy (rl extra: pip install -e ".[rl]")')
    from stable_baselines3.common.vec_env import VecVideoRecorder

    from wheelloader.envs.sb3 import make_sb3_vec_env

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make_sb3_vec_env(n_envs=2, seed=0, max_episode_steps=10, render_mode="rgb_array")
        rec = VecVideoRecorder(env, str(tmp_path), record_video_trigger=lambda step: step == 0, video_length=5)
        rec.reset()
        for _ in range(8):
            rec.step(np.tile(env.action_space.sample(), (2, 1)))
        rec.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0


def test_a_policy_trained_with_the_payload_model_says_so_for_its_rollouts(tmp_path):
    """``--force-model fee-payload``: config.json records the training env's model, where the policy strategies
    read the env to roll the policy out in."""
    from wheelloader.policy_strategies import policy_env_kwargs

    out = tmp_path / "ppo"
    _run("ppo.py", "--total-timesteps", "32", "--n-steps", "16", "--batch-size", "16", "--n-envs", "2",
         "--no-progress-bar", "--eval-soils", "gravel", "--eval-seeds", "1000", "--eval-freq", "0",
         "--checkpoint-freq", "0", "--force-model", "fee-payload", "--out", str(out))
    config = json.loads((out / "config.json").read_text())
    assert config["env_kwargs"] == {"force_model": "fee-payload"} and config["args"]["force_model"] == "fee-payload"
    assert policy_env_kwargs(out / "model.zip") == {"force_model": "fee-payload"}
