"""A policy closed loop in the MPM plant (references/mpm/closed_loop.py): the env's observation built from the
plant's state, the env's kinematics and cycle-end rules; the policy strategies that use it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wheelloader.envs.config import EnvConfig
from wheelloader.estimator import Bucket, BucketPath, Pile, bezier_path
from wheelloader.policy_strategies import EnvController, PolicyClosedLoop, PolicyPath, policy_env_kwargs
from wheelloader.references.mpm import MPMPlant, SceneSettings
from wheelloader.references.mpm.closed_loop import ENVELOPE_AHEAD, envelope

# the tiny scene of tests/test_mpm.py
TINY_BUCKET = Bucket(floor_length=0.15, capacity=0.01)
TINY_PILE = Pile.trapezoid(height=0.25, top_length=0.3, ground_before=0.2)


def _need_taichi() -> None:
    pytest.importorskip("taichi", reason='taichi not installed: pip install "wheelloader[mpm]"')


def tiny_path() -> BucketPath:
    return bezier_path((-0.03, 0.05), (0.30, 0.03), (0.38, 0.30), duration=1.2, rate=30.0,
                       angle_start=math.radians(-5.0), angle_end=math.radians(40.0), curl_from=0.5, name="tiny")


def tiny_plant() -> MPMPlant:
    return MPMPlant(0.03, bucket=TINY_BUCKET, settle_time=0.1, scene=SceneSettings(bed_depth=0.1, wall_margin=0.2),
                    settle_cache=False, threads=1)


def _config(**changes) -> EnvConfig:
    return EnvConfig.from_kwargs("test", pile=TINY_PILE, bucket=TINY_BUCKET, **changes)


class Recorder:
    """A controller with a fixed action that keeps every observation it is given."""

    name = "recorder"

    def __init__(self, action, env_config: EnvConfig) -> None:
        self.action = np.asarray(action, dtype=np.float32)
        self.env_config = env_config
        self.seen: list[np.ndarray] = []

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.seen.append(obs.copy())
        return self.action


def test_the_envelope_covers_the_path_and_its_margins():
    cfg = _config()
    path = tiny_path()
    xs, zs, domain = envelope(path, cfg)
    assert xs[1] == pytest.approx(min(cfg.x_limits[1], float(np.max(path.x)) + ENVELOPE_AHEAD))
    assert zs[0] == cfg.z_limits[0] and zs[1] > float(np.max(path.z))
    assert (domain.t[0], domain.x[0], domain.z[0], domain.angle[0]) == (path.t[0], path.x[0], path.z[0],
                                                                        path.blade_angle[0])
    assert {float(a) for a in domain.angle[1:]} == set(cfg.blade_angle_limits)


def test_the_controller_sees_the_plants_state_through_the_envs_kinematics():
    """Each observation is the env's entry table filled from the plant: the pose and velocity the env's kinematics
    gave (rate-limited from rest), the plant's fill over the capacity, its force in kN; the log is the commanded
    poses; the cycle ends by the env's rules."""
    _need_taichi()
    cfg = _config()
    ctl = Recorder([0.5, 0.0, 0.0], cfg)
    path = tiny_path()
    log = tiny_plant().dig(path, TINY_PILE, "sand", seed=0, controller=ctl)
    meta = log.metadata["closed_loop"]
    n = len(log.path.t)
    assert meta["steps"] == n - 1 == len(ctl.seen) and meta["controller"] == "recorder"
    assert meta["end"] in ("exit", "stall", "step limit")
    np.testing.assert_allclose(np.diff(log.path.t), cfg.dt, rtol=1e-9)
    dv = cfg.speed_step
    vx = np.diff(log.path.x) / cfg.dt
    # from rest, the velocity rises by the rate limit per step until it reaches the command (or the envelope holds)
    expected = np.minimum(dv * np.arange(1, n), 0.5 * cfg.loader.max_speed)
    free = ~np.isclose(log.path.x[1:], meta["envelope"]["x"][1])
    np.testing.assert_allclose(vx[free], expected[free], rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(log.path.z, log.path.z[0])
    obs = np.array(ctl.seen)
    low, high = cfg.observation_limits
    for k in range(1, len(obs)):  # the observation before step k+1 is the state after step k
        np.testing.assert_allclose(obs[k, :3], np.clip([log.path.x[k], log.path.z[k], log.path.blade_angle[k]],
                                                       low[:3], high[:3]), rtol=1e-6, atol=1e-6)
        assert obs[k, 3] == pytest.approx(vx[k - 1], rel=1e-5, abs=1e-6)
        assert obs[k, 9] == pytest.approx(min(log.fill_volume[k] / TINY_BUCKET.capacity, 1.0), rel=1e-5, abs=1e-6)
    assert obs[0, 10] == obs[0, 11] == 0.0  # at rest out of the soil, before any step
    assert np.max(obs[:, 9]) > 0.0 and np.max(np.abs(obs[:, 10])) > 0.0  # the plant's fill and force reach it
    assert obs.shape[1] == 12 + len(cfg.lookahead)


def test_a_force_above_the_loaders_limit_ends_the_cycle_as_a_stall():
    _need_taichi()
    weak = _config(loader={"max_push_force": 1.0, "max_lift_force": 1.0})
    log = tiny_plant().dig(tiny_path(), TINY_PILE, "sand", seed=0, controller=Recorder([0.8, -0.1, 0.0], weak))
    meta = log.metadata["closed_loop"]
    assert meta["end"] == "stall" and meta["steps_above_limits"] == weak.stall_patience == 1
    assert max(log.tangential[-1], log.normal[-1]) > 0.0


def test_the_bucket_is_held_at_the_envelope():
    _need_taichi()
    cfg = _config()
    short = BucketPath(np.array([0.0, 0.1]), np.array([-0.03, 0.0]), np.array([0.05, 0.05]),
                       np.radians([-5.0, -5.0]), name="short")
    ctl = Recorder([1.0, 0.0, 0.0], cfg)
    log = tiny_plant().dig(short, TINY_PILE, "sand", seed=0, controller=ctl)
    meta = log.metadata["closed_loop"]
    assert meta["envelope_steps"] > 0
    assert np.max(log.path.x) == pytest.approx(0.0 + ENVELOPE_AHEAD)


class _Steady:
    """A stand-in for a trained policy: a fixed function of the observation (its fill included)."""

    def predict(self, obs, deterministic=True):
        action = np.array([0.6, 0.15 - 0.3 * float(obs[1]) + 0.8 * float(obs[9]), 0.2 * np.tanh(float(obs[0]))],
                          dtype=np.float32)
        return np.clip(action, -1.0, 1.0), None


def test_the_closed_loop_strategy_plans_its_fee_env_path_and_hands_the_policy_on():
    pile = Pile.trapezoid()
    path = PolicyPath(_Steady()).plan(pile)
    closed = PolicyClosedLoop(_Steady(), env_kwargs={"force_model": "fee-payload"}).plan(pile)
    assert closed.path is not None and isinstance(closed.controller, EnvController)
    assert closed.controller.env_config.force_model == "fee-payload"
    assert not np.array_equal(closed.path.x, path.path.x)  # rolled out in the fee-payload env: its fill differs
    same = PolicyClosedLoop(_Steady()).plan(pile)
    np.testing.assert_array_equal(same.path.x, path.path.x)
    obs = np.zeros(same.controller.env_config.observation_limits[0].shape, dtype=np.float32)
    np.testing.assert_array_equal(same.controller(obs), _Steady().predict(obs)[0])


def test_a_policy_is_rolled_out_in_the_env_its_config_names(tmp_path):
    zip_path = tmp_path / "model.zip"
    assert policy_env_kwargs(zip_path) == {}  # no config.json: the env's defaults
    (tmp_path / "config.json").write_text(json.dumps({"env_kwargs": {"force_model": "fee-payload", "other": 1}}))
    assert policy_env_kwargs(zip_path) == policy_env_kwargs(str(zip_path)) == {"force_model": "fee-payload"}


def test_a_plants_own_log_with_the_bed_pushing_up_is_read_back_unchecked(tmp_path):
    """A closed-loop bucket that scrapes the MPM bed below the pile's ground feels the bed push it up: F_N < 0 in
    most samples in soil. CycleLog.load refuses that as a likely sign flip; the loop's own saved cycles are read
    with check=False."""
    from wheelloader.estimator import CycleLog, CycleLogError
    from wheelloader.saved_loops import load_saved_cycle, save_cycle

    t = np.linspace(0.0, 1.0, 11)
    path = BucketPath(t, 0.5 + 0.1 * t, 0.01 + 0 * t, 0 * t)
    normal = np.full(11, -1e3)
    normal[0] = 50.0  # positive out of the soil, before the cut
    log = CycleLog(path, np.full(11, 2e3), normal, Pile.trapezoid(), fill_volume=np.linspace(0, 0.02, 11))
    save_cycle(tmp_path, 1, log)
    with pytest.raises(CycleLogError, match="F_N is negative"):
        load_saved_cycle(tmp_path, 1)
    back = load_saved_cycle(tmp_path, 1, check=False)
    np.testing.assert_array_equal(back.normal, log.normal)
