"""One force model everywhere: for every name of ``FORCE_MODELS`` the estimator (NumPy arrays), the env (one
sample per step, single and batched) and the planner (CasADi) compute the same forces and the same fill."""

from __future__ import annotations

import pickle
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.config import pile_toe
from wheelloader.envs.scripted import PathTracker
from wheelloader.envs.vector import BucketLoadingVectorEnv
from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    DEFAULT_PAYLOAD,
    FORCE_MODELS,
    ParameterError,
    PayloadOptions,
    contact_state,
    default_path,
    soil_forces,
)
from wheelloader.estimator.force_models import check_force_model, cycle_contact_state, model_options_for
from wheelloader.estimator.payload import kept_volume

MAIN_ID = "wheelloader/BucketLoading-v0"


def _dig(name: str, seed: int = 3, **settings):
    """Track the paper's Bezier path in a noise-free env of force model ``name`` to the cycle's end; the
    per-step record, the carved volume and the env."""
    env = BucketLoadingEnv(force_model=name, sensor_noise=0.0, **settings)
    path = default_path(pile_toe(env.cfg.pile), rate=env.cfg.control_rate)
    tracker = PathTracker(path, env.cfg.loader, env.cfg.control_rate)
    obs, _ = env.reset(seed=seed)
    carved, infos = [0.0], []
    for _ in range(900):
        obs, _, terminated, truncated, info = env.step(tracker(obs))
        infos.append(info)
        carved.append(info["carved_volume"])
        if terminated or truncated:
            break
    record = env.episode_record()
    assert not any(i["stalled"] for i in infos)
    return env, record, np.asarray(carved), infos


def _estimator_forces(name: str, env, record, carved):
    """The estimator's forces (arrays) on the env's samples: its geometry, the carved fill as surcharge and,
    where the model carries a payload, the env's kept soil and its acceleration this step."""
    cfg = env.cfg
    x, z, th = record["x"], record["z"], record["blade_angle"]
    v = np.vstack([[0.0, 0.0], np.column_stack([np.diff(x), np.diff(z)]) / cfg.dt])  # realised, from rest
    acc = np.vstack([[0.0, 0.0], np.diff(v, axis=0) / cfg.dt])
    state = contact_state(x, z, th, env.start_pile, cfg.bucket, slope_window=cfg.slope_window, fill_volume=carved,
                          acceleration=acc)
    payload = check_force_model(name, cfg.payload)
    if payload is not None:
        state = replace(state, carried_volume=record["fill"])
    return soil_forces(env.soil, state, cfg.bucket, model_options_for(name, DEFAULT_OPTIONS))


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_env_single_samples_are_the_estimators_arrays(name):
    env, record, carved, infos = _dig(name)
    assert len(record["x"]) == len(carved) > 100
    forces = _estimator_forces(name, env, record, carved)
    np.testing.assert_allclose(record["true_F_T"], forces.tangential, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(record["true_F_N"], forces.normal, rtol=1e-9, atol=1e-6)
    assert np.array_equal(record["flags"], forces.flags)
    # the env's fill is the model's fill of the path: the carving (fee) or the payload's kept soil of it
    log = env.last_cycle_log()
    state = cycle_contact_state(log, name, env.cfg.payload, env.cfg.slope_window, "model")
    model_fill = state.fill_volume if state.carried_volume is None else state.carried_volume
    np.testing.assert_allclose(log.fill_volume, model_fill, rtol=1e-9, atol=1e-12)
    assert infos[-1]["fill_volume"] == pytest.approx(model_fill[-1], rel=1e-9)


def test_payload_fill_is_kept_soil_and_its_weight_stays_after_exit():
    _, fee, fee_carved, fee_infos = _dig("fee")
    env, rec, carved, infos = _dig("fee-payload")
    cap = env.cfg.bucket.capacity
    # same path, same carving: the payload keeps part of what the FEE's fill counts, up to its heaped capacity
    np.testing.assert_allclose(carved, fee_carved[:carved.size], rtol=1e-9, atol=1e-12)
    assert 0.0 < rec["fill"][-1] < carved[-1]
    assert rec["fill"][-1] <= DEFAULT_PAYLOAD.heap_factor * cap + 1e-12
    last = infos[-1]
    assert last["fill_fraction"] == pytest.approx(rec["fill"][-1] / cap)
    assert last["carved_volume"] == pytest.approx(carved[-1])
    # reward_fill sums to the kept fill per capacity (the fill gained each step)
    assert sum(i["reward_fill"] for i in infos) == pytest.approx(rec["fill"][-1] / cap, rel=1e-9)
    # after the tip left the soil the FEE's force is 0, the payload's is the kept soil's weight (and inertia)
    # (a cycle ends with the tip out of the soil; its inertia is within the loader's acceleration, 2 m/s^2 a
    # component, so within 0.29 of the weight)
    assert env.cycle_ends == ("exit",) and infos[-1]["depth"] <= 0.0 and fee_infos[-1]["depth"] <= 0.0
    weight = env.soil.gamma * 9.81 * rec["fill"][-1]
    assert np.hypot(rec["true_F_T"][-1], rec["true_F_N"][-1]) == pytest.approx(weight, rel=0.29)
    assert fee["true_F_T"][-1] == 0.0 and fee["true_F_N"][-1] == 0.0


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_gym_make_pickle_check_env_and_vector_env_take_the_model(name):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(MAIN_ID, force_model=name)
    check_env(env.unwrapped, skip_render_check=True)
    base = env.unwrapped
    assert base.cfg.force_model == name
    clone = pickle.loads(pickle.dumps(base))
    assert clone.cfg.force_model == name and clone.cfg.payload == base.cfg.payload
    vec = gym.make_vec(MAIN_ID, num_envs=2, force_model=name)
    assert vec.unwrapped.cfg.force_model == name
    _, info = vec.reset(seed=0)[0], vec.step(np.zeros((2, 3), dtype=np.float32))[-1]
    assert "carved_volume" in info and info["_carved_volume"].all()
    rllib = BucketLoadingEnv({"force_model": name})
    assert rllib.cfg.force_model == name
    meta = base.cfg.to_dict()
    assert ("force_model" in meta) == (name != "fee")


def test_payload_settings_are_checked():
    cfg = BucketLoadingEnv(force_model="fee-payload", payload={"retention": 0.5}).cfg
    assert cfg.payload == PayloadOptions(retention=0.5)
    assert BucketLoadingEnv(force_model="fee-payload").cfg.payload == DEFAULT_PAYLOAD
    assert BucketLoadingEnv().cfg.payload is None
    with pytest.raises(ParameterError, match="fee-payload"):
        BucketLoadingEnv(payload={"retention": 0.5})
    with pytest.raises(ParameterError, match="force_model"):
        BucketLoadingEnv(force_model="fea")
    with pytest.raises(ParameterError, match="unknown key"):
        BucketLoadingEnv(force_model="fee-payload", payload={"retension": 0.5})
    with pytest.raises(ParameterError, match="retention"):
        BucketLoadingVectorEnv(num_envs=2, force_model="fee-payload", payload={"retention": 0.0})


def test_batched_fill_is_the_kept_volume_of_its_removed_volume():
    vec = BucketLoadingVectorEnv(num_envs=3, force_model="fee-payload", sensor_noise=0.0)
    vec.reset(seed=1)
    act = np.tile(np.array([[0.6, -0.05, 0.0]], dtype=np.float32), (3, 1))
    for _ in range(60):
        _, _, _, _, info = vec.step(act)
    cap = vec.cfg.bucket.capacity
    assert np.all(info["carved_volume"] > 0.0)
    # what was removed is at least what was carved into the bucket; the kept soil is the payload's of it
    removed = vec.call("episode_record", current=True)
    assert len(removed) == 3
    np.testing.assert_array_less(info["fill_volume"], info["carved_volume"] + 1e-12)
    assert np.all(info["fill_volume"] <= kept_volume(np.full(3, 10.0), cap, DEFAULT_PAYLOAD) + 1e-12)
