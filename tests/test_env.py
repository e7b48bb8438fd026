"""Tests of the single bucket-loading env (wheelloader.envs)."""

from __future__ import annotations

import json
import math
import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import wheelloader.envs
from wheelloader.envs import ENV_IDS, REWARD_TERMS, BucketLoadingEnv
from wheelloader.envs.scripted import run_path
from wheelloader.estimator import PRESET_NAMES, Loader, Pile, preset, soil_forces
from wheelloader.estimator.errors import ParameterError

MAIN_ID = "wheelloader/BucketLoading-v0"


def _digging_actions(n: int, seed: int) -> np.ndarray:
    """Random actions biased into the pile (so that episodes dig, stall and carve)."""
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (n, 3)).astype(np.float32)
    acts[:, 0] = np.abs(acts[:, 0])
    return acts


def _rollout(env: gym.Env, seed: int, actions: np.ndarray) -> list[tuple]:
    out = []
    obs, _ = env.reset(seed=seed)
    out.append((obs.copy(), 0.0, False, False, {}))
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs.copy(), reward, terminated, truncated, info))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append((obs.copy(), 0.0, False, False, {}))
    return out


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env_passes_without_warnings(env_id):
    env = gym.make(env_id, render_mode="rgb_array" if env_id == MAIN_ID else None)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped, skip_render_check=env_id != MAIN_ID)
    assert [str(w.message) for w in caught] == []
    env.close()


@pytest.mark.parametrize("env_id", [MAIN_ID, "wheelloader/BucketLoadingMultiCycle-v0"])
def test_sb3_check_env_passes_without_warnings(env_id):
    sb3_env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_env_checker.check_env(env, warn=True)
    assert [str(w.message) for w in caught] == []


def test_import_registers_ids_and_does_not_import_matplotlib():
    code = ("import sys, gymnasium as gym, wheelloader.envs; "
            "gym.make('wheelloader/BucketLoading-v0').reset(seed=0); "
            "assert 'matplotlib' not in sys.modules, 'matplotlib imported'; "
            "assert all(i in gym.registry for i in wheelloader.envs.ENV_IDS)")
    subprocess.run([sys.executable, "-c", code], check=True)


@pytest.mark.parametrize("env_id", [MAIN_ID, "wheelloader/BucketLoadingBeyondModel-v0",
                                    "wheelloader/BucketLoadingMultiCycle-v0"])
def test_same_seed_and_actions_give_identical_trajectories(env_id):
    actions = _digging_actions(300, 1)
    a = _rollout(gym.make(env_id), 7, actions)
    b = _rollout(gym.make(env_id), 7, actions)
    assert len(a) == len(b)
    for sa, sb in zip(a, b, strict=True):
        np.testing.assert_array_equal(sa[0], sb[0])
        assert sa[1:4] == sb[1:4]
        assert sa[4] == sb[4]


def test_pickled_env_continues_identically():
    env = gym.make("wheelloader/BucketLoadingBeyondModel-v0")
    env.reset(seed=3)
    actions = _digging_actions(80, 2)
    for a in actions[:40]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    for a in actions[40:]:
        o1, r1, t1, u1, _ = env.step(a)
        o2, r2, t2, u2, _ = clone.step(a)
        np.testing.assert_array_equal(o1, o2)
        assert (r1, t1, u1) == (r2, t2, u2)
        if t1 or u1:
            break


def test_reward_equals_sum_of_info_terms():
    env = gym.make(MAIN_ID, reward_weights={"validity": 0.5, "force": 2.0},
                   loader={"max_push_force": 6000.0}, stall_patience=3)
    env.reset(seed=0)
    seen = dict.fromkeys(REWARD_TERMS, False)
    for a in _digging_actions(600, 4):
        _, reward, terminated, truncated, info = env.step(a)
        assert reward == sum(info[k] for k in REWARD_TERMS)
        for k in REWARD_TERMS:
            seen[k] |= info[k] != 0.0
        if terminated or truncated:
            env.reset()
    assert all(seen.values()), seen


_CONFIGS = [
    {},
    {"soil": "random", "truth": {"compaction": 1.0, "rate_resistance": 20_000.0, "stone_rate": 2.0, "drift": 0.1},
     "keep_pile": True, "relax": True},
    {"soil": {"phi": (0.3, 0.7), "cohesion": (0.0, 20_000.0), "base": "dirt"}, "sensor_noise": 1000.0,
     "loader": {"max_push_force": 5000.0}, "stall_patience": 4},
    {"cycles_per_episode": 3, "pile": {"shape": "ideal_slope", "angle": 0.6}, "control_rate": 30.0},
]


def _check_random_steps(config: dict, steps: int, seed: int) -> None:
    env = gym.make(MAIN_ID, **config)
    space = env.observation_space
    obs, _ = env.reset(seed=seed)
    assert space.contains(obs)
    rng = np.random.default_rng(seed)
    for i in range(steps):
        a = rng.uniform(-1, 1, 3).astype(np.float32)
        if i % 3:
            a[0] = abs(a[0])
        obs, reward, terminated, truncated, _ = env.step(a)
        assert np.all(np.isfinite(obs)) and math.isfinite(reward)
        assert space.contains(obs), (obs, space.low, space.high)
        if terminated or truncated:
            obs, _ = env.reset()
            assert space.contains(obs)


@pytest.mark.parametrize("config", _CONFIGS)
def test_observations_finite_and_in_space_smoke(config):
    _check_random_steps(config, 1000, 11)


@pytest.mark.slow
@pytest.mark.parametrize("soil", PRESET_NAMES)
@pytest.mark.parametrize("config", _CONFIGS)
def test_observations_finite_and_in_space_10k(config, soil):
    config = dict(config)
    config.setdefault("soil", soil)
    _check_random_steps(config, 10_000, 5)


def test_env_forces_equal_shared_model_on_recorded_path():
    env = gym.make(MAIN_ID, soil="dirt")
    result = run_path(env, seed=2)
    assert result["terminated"]
    base = env.unwrapped
    log = base.last_cycle_log()
    rec = base.episode_record()
    model = soil_forces(preset("dirt"), log.contact_state(), log.bucket)
    np.testing.assert_allclose(rec["true_F_T"], model.tangential, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(rec["true_F_N"], model.normal, rtol=1e-9, atol=1e-6)
    np.testing.assert_array_equal(rec["flags"], model.flags)
    noise = np.concatenate([log.tangential - rec["true_F_T"], log.normal - rec["true_F_N"]])
    assert 100.0 < noise.std() < 200.0  # default sensor noise 150 N


def test_cycle_log_contents_and_round_trip(tmp_path):
    env = gym.make(MAIN_ID)
    run_path(env, seed=5)
    log = env.unwrapped.last_cycle_log()
    assert log.pile == Pile.trapezoid()
    assert log.pile_after.area() < log.pile.area()
    removed = (log.pile.area() - log.pile_after.area()) * log.bucket.width
    assert removed == pytest.approx(log.fill_volume[-1], rel=1e-9)
    assert np.all(np.diff(log.fill_volume) >= 0.0)
    assert log.metadata["true_soil"] == preset("gravel").to_dict()
    assert log.metadata["seed"] == 5 and log.metadata["end"] == "exit"
    path = log.save(tmp_path / "cycle.csv")
    back = type(log).load(path)
    np.testing.assert_allclose(back.tangential, log.tangential)
    assert back.metadata["true_soil"] == log.metadata["true_soil"]


def test_stall_holds_the_bucket_and_terminates():
    loader = Loader(max_push_force=2000.0)
    env = gym.make(MAIN_ID, loader=loader, stall_patience=2, sensor_noise=0.0)
    env.reset(seed=0)
    stalled_steps = []
    for _ in range(400):
        before = env.unwrapped.render_state()
        obs, reward, terminated, truncated, info = env.step(np.array([1.0, -0.2, 0.0], np.float32))
        if info["stalled"]:
            stalled_steps.append(info)
            assert obs[0] == np.float32(before["x"]) and obs[1] == np.float32(before["z"])
            assert obs[3] == 0.0 and obs[4] == 0.0
            assert info["reward_stall"] == -1.0 and info["reward_fill"] == 0.0
        if terminated:
            break
    assert terminated and len(stalled_steps) >= 2 and info["stalled"]
    assert env.unwrapped.last_cycle_log().metadata["end"] == "stall"


def test_keep_pile_relax_and_soil_options():
    env = gym.make(MAIN_ID, soil="random")
    base = env.unwrapped
    run_path(env, seed=1)
    carved = base.last_cycle_log().pile_after
    env.reset(options={"keep_pile": True, "soil": "keep"})
    soil = base.soil
    assert base.render_state()["start_pile"] == carved
    env.reset(options={"keep_pile": True, "relax": math.radians(25.0), "soil": "keep"})
    relaxed = base.render_state()["start_pile"]
    assert relaxed != carved and relaxed.area() == pytest.approx(carved.area(), rel=1e-12)
    assert base.soil == soil
    env.reset(options={"soil": "lean_clay"})
    assert base.soil == preset("lean_clay")
    assert base.render_state()["start_pile"] == Pile.trapezoid()
    soils = [env.reset(options={"soil": "resample"})[1]["soil"] for _ in range(12)]
    assert len({tuple(sorted(s.items())) for s in soils}) > 1
    assert all(type(s) is dict and json.loads(json.dumps(s)) == s for s in soils)  # plain, loggable
    with pytest.raises(ParameterError, match="unknown key"):
        env.reset(options={"keep_piles": True})


def test_soil_drift_between_cycles():
    env = gym.make(MAIN_ID, truth={"drift": 0.05})
    env.reset(seed=0)
    first = env.unwrapped.soil
    env.reset()
    second = env.unwrapped.soil
    assert first == preset("gravel") and second != first
    assert not second.out_of_bounds()


def test_multi_cycle_episode_keeps_the_pile():
    env = gym.make("wheelloader/BucketLoadingMultiCycle-v0", truth=None, relax=False)
    base = env.unwrapped
    obs, _ = env.reset(seed=3)
    from wheelloader.envs.scripted import PathTracker
    from wheelloader.estimator import default_path

    tracker = PathTracker(default_path())
    cycles = 0
    for _ in range(3000):
        obs, _, terminated, truncated, info = env.step(tracker(obs))
        if info["cycle_done"]:
            cycles += 1
            tracker.reset()
        if terminated or truncated:
            break
    assert terminated and cycles == 5
    logs = base.cycle_logs()
    assert len(logs) == 5
    for prev, nxt in zip(logs, logs[1:], strict=False):
        assert nxt.pile == prev.pile_after
    # later cycles on the carved pile fill less (the pile face has moved away)
    assert logs[-1].fill_volume[-1] < logs[0].fill_volume[-1]


def test_truth_options_change_forces_and_off_by_default():
    actions = np.tile(np.array([[0.6, 0.0, 0.0]], np.float32), (60, 1))
    records = {}
    for name, truth in (("model", None), ("compaction", {"compaction": 1.0}), ("stones", {"stone_rate": 50.0})):
        env = gym.make(MAIN_ID, truth=truth, sensor_noise=0.0, start_noise=(0.0, 0.0, 0.0))
        env.reset(seed=0)
        infos = [env.step(a)[4] for a in actions]
        records[name] = np.array([i["force_tangential"] for i in infos])
    ins = records["model"] > 0
    assert ins.any()
    assert np.all(records["compaction"][ins] > records["model"][ins])
    assert np.max(records["stones"] - records["model"]) > 1000.0


def test_twin_has_calibrated_soil_and_no_noise():
    env = gym.make(MAIN_ID, truth={"stone_rate": 5.0})
    run_path(env, seed=0)
    twin = env.unwrapped.make_twin(preset("sand"))
    assert twin.soil == preset("sand") and twin.cfg.sensor_noise == 0.0 and not twin.cfg.truth.active
    twin.reset(options={"keep_pile": True})
    assert twin.render_state()["start_pile"] == env.unwrapped.last_cycle_log().pile_after
    for _ in range(40):
        _, _, term, _, info = twin.step(np.array([0.8, 0.1, 0.0], np.float32))
        assert info["measured_tangential"] == info["force_tangential"]
        if term:
            break


def test_energy_accumulates_work_on_soil_and_payload():
    env = gym.make(MAIN_ID)
    result = run_path(env, seed=0)
    info = result["info"]
    assert info["energy_soil"] > 1000.0 and info["energy_payload"] > 100.0
    # payload lifting work is at most W_load * lift height
    fill = info["fill_volume"]
    assert info["energy_payload"] <= preset("gravel").gamma * 9.81 * fill * 1.3


def test_rgb_array_render():
    env = gym.make(MAIN_ID, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(60):
        env.step(np.array([0.6, 0.05, 0.1], np.float32))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.std() > 10
    env.close()


def test_invalid_arguments_raise_parameter_error():
    with pytest.raises(ParameterError, match="control_rate"):
        BucketLoadingEnv(control_rate=0.0)
    with pytest.raises(ParameterError, match="soil"):
        BucketLoadingEnv(soil=42)
    with pytest.raises(ParameterError, match="truth"):
        BucketLoadingEnv(truth={"rocks": 1.0})
    with pytest.raises(ParameterError, match="render_mode"):
        BucketLoadingEnv(render_mode="ascii")
    with pytest.raises(ParameterError, match="stall_patience"):
        BucketLoadingEnv(stall_patience=0)


def test_observation_names_match_space_and_docstring():
    env = BucketLoadingEnv()
    names = env.cfg.obs_names()
    assert len(names) == env.observation_space.shape[0] == 17
    doc = BucketLoadingEnv.__doc__
    for section in ("## Action Space", "## Observation Space", "## Rewards", "## Starting State",
                    "## Episode End", "## Arguments", "## Version History"):
        assert section in doc
    assert np.all(np.isfinite(env.observation_space.low)) and np.all(np.isfinite(env.observation_space.high))
    assert wheelloader.envs.BucketLoadingEnv is BucketLoadingEnv


def test_sb3_ppo_smoke():
    sb3 = pytest.importorskip("stable_baselines3")
    env = gym.make(MAIN_ID)
    model = sb3.PPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)


def _thin_layer_pile() -> Pile:
    """4 cm of soil over the ground from x = 0 to 1 m, then a 30 deg face (a carved pile's residue)."""
    return Pile.from_polyline([-0.5, 0.0, 0.02, 1.0, 1.0 + 1.0 / math.tan(math.radians(30.0)), 4.0],
                              [0.0, 0.0, 0.04, 0.04, 1.0, 1.0])


def _graze_and_rise(**kwargs) -> dict:
    """Skim the layer 2 cm deep, then rise 6 cm above it and hold: the info of the last step."""
    from wheelloader.envs.scripted import PathTracker
    from wheelloader.estimator import BucketPath

    t = np.linspace(0.0, 2.0, 121)
    x = np.interp(t, [0.0, 0.8, 1.4, 2.0], [-0.1, 0.3, 0.45, 0.45])
    z = np.interp(t, [0.0, 0.3, 0.8, 1.4, 2.0], [0.03, 0.02, 0.02, 0.10, 0.10])
    path = BucketPath(t, x, z, np.full_like(t, math.radians(-5.0)), "graze")
    env = gym.make("wheelloader/BucketLoading-v0", pile=_thin_layer_pile(), truth=None, sensor_noise=0.0,
                   start_pose=(-0.1, 0.03, math.radians(-5.0)), start_noise=(0.0, 0.0, 0.0), **kwargs)
    obs, _ = env.reset(seed=0)
    tracker = PathTracker(path)
    touched = False
    for _ in range(150):
        obs, _, terminated, truncated, info = env.step(tracker(obs))
        touched |= info["depth"] > 0.0
        if terminated or truncated:
            break
    assert touched
    return info


def test_grazing_a_thin_layer_ends_the_cycle_only_under_the_first_exit_rule():
    info = _graze_and_rise(exit_min_fill=0.05)
    assert info["fill_fraction"] < 0.05 and not info["cycle_done"]
    # the default rule ends a cycle at the first exit after any contact
    assert _graze_and_rise()["cycle_done"]
    with pytest.raises(ParameterError, match="exit_min_fill"):
        gym.make("wheelloader/BucketLoading-v0", exit_min_fill=1.5)


def test_cycle_ends_says_why_kept_cycles_ended():
    env = gym.make(MAIN_ID, sensor_noise=0.0)
    env.reset(seed=0)
    assert env.unwrapped.cycle_ends == ()
    run_path(env, seed=1)
    env.reset(seed=2)
    for _ in range(5):
        env.step(np.array([0.5, 0.0, 0.0], np.float32))
    env.reset(seed=3)  # a cycle in progress is kept as ended by "reset"
    assert env.unwrapped.cycle_ends == ("exit", "reset")
    assert [log.metadata["end"] for log in env.unwrapped.cycle_logs()] == ["exit", "reset"]
    stalling = gym.make(MAIN_ID, loader=Loader(max_push_force=2000.0))
    stalling.reset(seed=0)
    for _ in range(400):
        *_, terminated, truncated, _ = stalling.step(np.array([1.0, -0.2, 0.0], np.float32))
        if terminated or truncated:
            break
    assert stalling.unwrapped.cycle_ends == ("stall",)
