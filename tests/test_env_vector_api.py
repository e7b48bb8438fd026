"""The batched env's public vector API against Gymnasium's own SyncVectorEnv of single envs: partial reset
(``reset_mask``), reset and step ``info`` keys with ``_key`` masks, ``get_attr``/``set_attr``/``call``,
``render``, and Gymnasium's vector wrappers."""

from __future__ import annotations

import dataclasses
import inspect
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.config import EnvConfig
from wheelloader.envs.vector import RESET_INFO_KEYS, STEP_INFO_KEYS, BucketLoadingVectorEnv
from wheelloader.estimator import Pile, preset
from wheelloader.estimator.errors import ParameterError

MAIN_ID = "wheelloader/BucketLoading-v0"


def _pair(n: int, max_steps: int, **kwargs):
    vec = gym.make_vec(MAIN_ID, num_envs=n, max_episode_steps=max_steps, **kwargs)
    sync = SyncVectorEnv([lambda: gym.make(MAIN_ID, max_episode_steps=max_steps, **kwargs) for _ in range(n)],
                         autoreset_mode=AutoresetMode.NEXT_STEP)
    return vec, sync


def _assert_info_equal(got: dict, want: dict, where: str) -> None:
    assert sorted(got) == sorted(want), where
    for key, value in want.items():
        mine = got[key]
        assert mine.shape == value.shape, (where, key)
        if key.startswith("_") or value.dtype == object or value.dtype == bool or value.dtype.kind == "i":
            assert mine.dtype == value.dtype, (where, key, mine.dtype, value.dtype)
            assert list(mine) == list(value), (where, key)
        else:
            np.testing.assert_allclose(mine, value, rtol=1e-6, atol=1e-6, err_msg=f"{where} {key}")


def test_partial_reset_and_infos_match_sync_vector_env_of_single_envs():
    n = 4
    vec, sync = _pair(n, 40, soil="random", loader={"max_push_force": 4000.0})
    obs_v, info_v = vec.reset(seed=7)
    obs_s, info_s = sync.reset(seed=7)
    np.testing.assert_allclose(obs_v, obs_s, rtol=1e-6, atol=1e-6)
    _assert_info_equal(info_v, info_s, "reset")
    rng = np.random.default_rng(1)
    seen = {"autoreset": 0, "partial": 0, "stall": 0}
    for t in range(160):
        if t in (25, 90, 91):  # partial resets (one of them right before an autoreset would happen)
            mask = rng.random(n) < 0.5
            mask[t % n] = True
            obs_v, info_v = vec.reset(options={"reset_mask": mask.copy()})
            obs_s, info_s = sync.reset(options={"reset_mask": mask.copy()})
            seen["partial"] += 1
            _assert_info_equal(info_v, info_s, f"partial reset at {t}")
        else:
            act = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
            act[:, 0] = np.abs(act[:, 0])
            obs_v, rew_v, term_v, trunc_v, info_v = vec.step(act)
            obs_s, rew_s, term_s, trunc_s, info_s = sync.step(act)
            np.testing.assert_allclose(rew_v, rew_s, rtol=1e-7, atol=1e-9)
            np.testing.assert_array_equal(term_v, term_s)
            np.testing.assert_array_equal(trunc_v, trunc_s)
            _assert_info_equal(info_v, info_s, f"step {t}")
            seen["autoreset"] += int("_soil" in info_s)
            seen["stall"] += int(info_s.get("stalled", np.zeros(1, bool)).any())
        np.testing.assert_allclose(obs_v, obs_s, rtol=1e-6, atol=1e-6, err_msg=f"t={t}")
    assert seen["autoreset"] > 0 and seen["partial"] == 3 and seen["stall"] > 0
    assert set(STEP_INFO_KEYS) <= set(info_v) or "_soil" in info_v
    vec.close()
    sync.close()


def test_info_keys_are_the_single_envs():
    env = gym.make(MAIN_ID)
    _, reset_info = env.reset(seed=0)
    *_, step_info = env.step(env.action_space.sample())
    assert tuple(reset_info) == RESET_INFO_KEYS
    assert set(step_info) == set(STEP_INFO_KEYS)
    vec = BucketLoadingVectorEnv(num_envs=2)
    _, info = vec.reset(seed=0)
    assert set(info) == set(RESET_INFO_KEYS) | {"_" + k for k in RESET_INFO_KEYS}
    *_, info = vec.step(vec.action_space.sample())
    assert set(info) == set(STEP_INFO_KEYS) | {"_" + k for k in STEP_INFO_KEYS}


def test_reset_mask_is_validated():
    vec = BucketLoadingVectorEnv(num_envs=3)
    with pytest.raises(ParameterError, match="first reset must reset every sub-env"):
        vec.reset(options={"reset_mask": np.array([True, False, False])})
    vec.reset(seed=0)
    for bad in ([True, False, True], np.array([1, 0, 1]), np.ones(2, dtype=bool)):
        with pytest.raises(ParameterError, match="reset_mask must be a NumPy bool array of shape"):
            vec.reset(options={"reset_mask": bad})
    with pytest.raises(ParameterError, match="at least one True"):
        vec.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    with pytest.raises(ParameterError, match="without a partial reset_mask"):
        vec.reset(options={"reset_mask": np.array([True, False, False]), "sensor_noise": 10.0})
    options = {"reset_mask": np.array([True, False, False])}
    vec.reset(options=options)
    assert "reset_mask" in options  # the caller's dict is not changed (Gymnasium's wrappers read it after)


def test_partial_reset_leaves_the_other_sub_envs_untouched():
    vec = BucketLoadingVectorEnv(num_envs=3)
    vec.reset(seed=0)
    for _ in range(20):
        obs, *_ = vec.step(np.tile([[1.0, 0.0, 0.0]], (3, 1)).astype(np.float32))
    obs2, info = vec.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(obs2[[0, 2]], obs[[0, 2]])
    assert list(info["_soil"]) == [False, True, False] and info["soil"][0] is None
    single = gym.make(MAIN_ID)
    single.reset(seed=1)
    for _ in range(20):
        single.step(np.array([1.0, 0.0, 0.0], np.float32))
    np.testing.assert_allclose(obs2[1], single.reset()[0], rtol=1e-6, atol=1e-6)


def test_gymnasium_vector_wrappers_with_partial_reset():
    from gymnasium.wrappers.vector import DictInfoToList, RecordEpisodeStatistics

    envs = DictInfoToList(RecordEpisodeStatistics(gym.make_vec(MAIN_ID, num_envs=3, max_episode_steps=30)))
    envs.reset(seed=0)
    episodes = 0
    for t in range(70):
        if t == 10:
            _, infos = envs.reset(options={"reset_mask": np.array([False, True, False])})
            assert "soil" in infos[1] and "soil" not in infos[0]
            continue
        _, _, term, trunc, infos = envs.step(envs.action_space.sample())
        episodes += sum("episode" in i for i in infos)
        assert len(infos) == 3
    assert episodes >= 3
    envs.close()


def test_get_attr_set_attr_and_call():
    vec = BucketLoadingVectorEnv(num_envs=3, soil="random", render_mode="rgb_array")
    vec.reset(seed=2)
    soils = vec.get_attr("soil")
    assert len(soils) == 3 and soils == tuple(gym.make(MAIN_ID, soil="random").reset(seed=2 + i)[1]["soil"]
                                               for i in range(3))
    assert vec.get_attr("render_mode") == ("rgb_array",) * 3
    assert vec.get_attr("cfg")[0] is vec.cfg
    assert all(isinstance(p, Pile) for p in vec.get_attr("start_pile"))
    assert all(isinstance(g, np.random.Generator) for g in vec.get_attr("np_random"))
    with pytest.raises(AttributeError):
        vec.get_attr("no_such_attribute")
    vec.set_attr("soil", "lean_clay")
    assert vec.get_attr("soil") == (preset("lean_clay"),) * 3
    vec.set_attr("soil", ["sand", "dirt", "gravel"])
    assert vec.get_attr("soil") == (preset("sand"), preset("dirt"), preset("gravel"))
    with pytest.raises(ParameterError, match="num_envs=3"):
        vec.set_attr("soil", ["sand", "dirt"])
    with pytest.raises(ParameterError, match="shared"):
        vec.set_attr("max_episode_steps", [1, 2, 3])
    vec.set_attr("max_episode_steps", 50)
    assert vec.max_episode_steps == 50
    with pytest.raises(ParameterError, match="cannot be set"):
        vec.set_attr("start_pile", None)
    frames = vec.call("render")
    assert len(frames) == 3 and all(f.dtype == np.uint8 and f.ndim == 3 for f in frames)
    assert vec.call("soil") == vec.get_attr("soil")
    assert vec.call("max_episode_steps") == (50, 50, 50)
    vec.close()


def test_single_env_keywords_are_typed_and_match_the_config():
    """Typed keyword arguments (Hopper-v5 style) with the names and defaults of EnvConfig, the one list of the
    settings, in both envs' signatures."""
    cfg_fields = {f.name: f for f in dataclasses.fields(EnvConfig)}
    for cls, own in ((BucketLoadingEnv, ("self", "render_mode", "max_episode_steps")),
                     (BucketLoadingVectorEnv, ("self", "num_envs", "max_episode_steps", "render_mode"))):
        env_params = inspect.signature(cls.__init__).parameters
        mine = {k: p for k, p in env_params.items() if k not in own}
        assert list(mine) == list(cfg_fields), cls
        for name, param in mine.items():
            assert param.kind is inspect.Parameter.KEYWORD_ONLY, name
            assert param.default == cfg_fields[name].default, name
            assert param.annotation is not inspect.Parameter.empty, name
    env = gym.make(MAIN_ID, soil="sand", sensor_noise=0.0, stall_patience=2)
    assert env.unwrapped.cfg.sensor_noise == 0.0 and env.unwrapped.cfg.stall_patience == 2
    with pytest.raises(TypeError, match="unexpected keyword"):
        BucketLoadingEnv(no_such_option=1)


def test_sb3_adapter_without_stable_baselines3_says_what_to_install():
    code = ("import sys; sys.modules['stable_baselines3'] = None\n"
            "try:\n    import wheelloader.envs.sb3\n"
            "except ImportError as exc:\n    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "wheelloader.envs.sb3 needs stable-baselines3" in out and "wheelloader[rl]" in out


def test_step_info_arrays_are_fresh_and_not_shared():
    """info arrays are not views of the env's state (they keep their values) and no two keys share one."""
    vec = BucketLoadingVectorEnv(num_envs=4)
    vec.reset(seed=0)
    act = np.full((4, 3), 0.5, np.float32)
    *_, info = vec.step(act)
    snapshot = {k: v.copy() for k, v in info.items()}
    for _ in range(5):
        vec.step(act)
    for key, value in snapshot.items():
        np.testing.assert_array_equal(info[key], value, err_msg=key)
    assert len({id(v) for v in info.values()}) == len(info)
