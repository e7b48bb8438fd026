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
        if isinstance(value, dict):  # nested info (the soil's parameters, SAME_STEP's final_info)
            _assert_info_equal(mine, value, f"{where} {key}")
            continue
        if key == "final_obs":
            assert [o is None for o in mine] == [o is None for o in value], where
            for a, b in zip(mine, value, strict=True):
                if b is not None:
                    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6, err_msg=f"{where} final_obs")
            continue
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
    assert list(info["_soil"]) == [False, True, False] and list(info["soil"]["_phi"]) == [False, True, False]
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
    assert len(soils) == 3 and tuple(s.to_dict() for s in soils) == tuple(
        gym.make(MAIN_ID, soil="random").reset(seed=2 + i)[1]["soil"] for i in range(3))
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
                     (BucketLoadingVectorEnv, ("self", "num_envs", "max_episode_steps", "render_mode",
                                               "autoreset_mode", "record_cycles"))):
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


def _assert_logs_equal(mine, want, where: str) -> None:
    for name in ("t", "x", "z", "blade_angle"):
        np.testing.assert_allclose(getattr(mine.path, name), getattr(want.path, name), rtol=1e-9, atol=1e-9,
                                   err_msg=f"{where} path.{name}")
    for name in ("tangential", "normal", "fill_volume"):
        np.testing.assert_allclose(getattr(mine, name), getattr(want, name), rtol=1e-6, atol=1e-6,
                                   err_msg=f"{where} {name}")
    np.testing.assert_allclose(mine.pile.heights, want.pile.heights, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(mine.pile_after.heights, want.pile_after.heights, rtol=1e-9, atol=1e-9)
    meta_mine = {k: v for k, v in mine.metadata.items() if k not in ("source", "energy_soil", "energy_payload")}
    meta_want = {k: v for k, v in want.metadata.items() if k not in ("source", "energy_soil", "energy_payload")}
    assert meta_mine == meta_want, where
    for key in ("energy_soil", "energy_payload"):
        assert mine.metadata[key] == pytest.approx(want.metadata[key], rel=1e-7, abs=1e-6), (where, key)
    assert mine.metadata["source"].endswith("BucketLoadingVectorEnv")


def _assert_records_equal(vec, sync, where: str) -> None:
    """The single env's public methods through ``call``: cycle ends, kept cycles, the current record."""
    assert vec.call("cycle_ends") == sync.call("cycle_ends"), where
    for i, (mine, want) in enumerate(zip(vec.call("cycle_logs"), sync.call("cycle_logs"), strict=True)):
        assert len(mine) == len(want), (where, i)
        for k, (a, b) in enumerate(zip(mine, want, strict=True)):
            _assert_logs_equal(a, b, f"{where} env {i} cycle {k}")
    for i in range(vec.num_envs):
        try:
            want = sync.envs[i].unwrapped.episode_record(current=True)
        except ParameterError:
            with pytest.raises(ParameterError, match="no cycle in progress"):
                vec.unwrapped.episode_record(i, current=True)
            continue
        mine = vec.unwrapped.episode_record(i, current=True)
        assert sorted(mine) == sorted(want)
        for key, value in want.items():
            assert mine[key].dtype == value.dtype, (where, i, key)
            np.testing.assert_allclose(mine[key], value, rtol=1e-6, atol=1e-6, err_msg=f"{where} env {i} {key}")


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP, AutoresetMode.DISABLED],
                         ids=lambda m: m.name)
def test_autoreset_modes_seeds_and_records_match_sync_vector_env(mode):
    """Each autoreset mode step by step against SyncVectorEnv of single envs: observations, rewards, ends,
    infos (final_obs / final_info in SAME_STEP), per-sub-env seeds, and what call() gives of the single env's
    public methods (cycle ends, cycle logs, the current record)."""
    n, kwargs = 4, {"soil": "random", "loader": {"max_push_force": 4000.0}, "max_episode_steps": 45}
    vec = gym.make_vec(MAIN_ID, num_envs=n, autoreset_mode=mode, **kwargs)
    sync = SyncVectorEnv([lambda: gym.make(MAIN_ID, **kwargs) for _ in range(n)], autoreset_mode=mode)
    assert vec.metadata["autoreset_mode"] is mode
    for env in (vec, sync):
        env.set_attr("max_logged_cycles", 3)
    obs_v, info_v = vec.reset(seed=11)
    obs_s, info_s = sync.reset(seed=11)
    assert vec.np_random_seed == sync.np_random_seed == tuple(range(11, 11 + n))
    assert vec.get_attr("np_random_seed") == sync.get_attr("np_random_seed")
    _assert_info_equal(info_v, info_s, "reset")
    rng = np.random.default_rng(3)
    ends = 0
    for t in range(150):
        act = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
        act[:, 0] = 0.5 + 0.5 * np.abs(act[:, 0])  # into the pile
        if (t // 15) % 2:
            act[:, 1] = np.abs(act[:, 1])  # and up: some cycles end by an exit
        obs_v, rew_v, term_v, trunc_v, info_v = vec.step(act)
        obs_s, rew_s, term_s, trunc_s, info_s = sync.step(act)
        np.testing.assert_allclose(obs_v, obs_s, rtol=1e-6, atol=1e-6, err_msg=f"step {t}")
        np.testing.assert_allclose(rew_v, rew_s, rtol=1e-7, atol=1e-9)
        np.testing.assert_array_equal(term_v, term_s)
        np.testing.assert_array_equal(trunc_v, trunc_s)
        _assert_info_equal(info_v, info_s, f"step {t}")
        ended = term_s | trunc_s
        ends += int(ended.sum())
        if t % 10 == 0 or ended.any():
            _assert_records_equal(vec, sync, f"step {t}")
        if mode is AutoresetMode.DISABLED and ended.any():
            with pytest.raises(ParameterError, match="autoreset_mode DISABLED: sub-env"):
                vec.step(act)
            obs_v, info_v = vec.reset(options={"reset_mask": ended.copy()})
            obs_s, info_s = sync.reset(options={"reset_mask": ended.copy()})
            np.testing.assert_allclose(obs_v, obs_s, rtol=1e-6, atol=1e-6)
            _assert_info_equal(info_v, info_s, f"reset after {t}")
            _assert_records_equal(vec, sync, f"reset after {t}")
    reasons = sum(vec.call("cycle_ends"), ())
    assert ends >= 8 and max(len(e) for e in vec.call("cycle_ends")) == 3  # max_logged_cycles
    assert {"exit", "stall", "reset"} >= set(reasons) and "stall" in reasons and "reset" in reasons
    for i, log in enumerate(vec.call("last_cycle_log")):
        _assert_logs_equal(log, sync.envs[i].unwrapped.last_cycle_log(), f"last of env {i}")
    vec.close()
    sync.close()


def test_batched_env_refuses_what_it_cannot_do_with_a_clear_message():
    vec = BucketLoadingVectorEnv(num_envs=2, record_cycles=False)
    vec.reset(seed=0)
    with pytest.raises(ParameterError, match="record_cycles=False"):
        vec.call("last_cycle_log")
    with pytest.raises(ParameterError, match="make_twin needs the single env"):
        vec.call("make_twin")
    with pytest.raises(ParameterError, match="autoreset_mode must be one of"):
        BucketLoadingVectorEnv(num_envs=2, autoreset_mode="sometimes")
    vec = BucketLoadingVectorEnv(num_envs=2)
    vec.reset(seed=0)
    with pytest.raises(ParameterError, match="no finished cycle yet"):
        vec.call("last_cycle_log")
    vec.set_attr("np_random", [np.random.default_rng(1), np.random.default_rng(2)])
    assert vec.np_random_seed == (-1, -1)
