"""Scripted Bezier-following policy: fills the bucket and its cycle calibrates back to the hidden soil."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs.scripted import PathTracker, path_actions, run_path
from wheelloader.estimator import Loader, default_path, preset, soil_forces
from wheelloader.estimator.errors import ParameterError

MAIN_ID = "wheelloader/BucketLoading-v0"


@pytest.mark.parametrize("soil", ["gravel", "dirt", "lean_clay"])
def test_scripted_bezier_policy_fills_at_least_80_percent(soil):
    env = gym.make(MAIN_ID, soil=soil)
    for seed in range(3):
        result = run_path(env, seed=seed)
        assert result["terminated"] and not result["stalled"]
        assert result["fill_fraction"] >= 0.8
        assert result["reward"] > 0.5


def test_open_loop_path_actions_reproduce_the_path():
    path = default_path()
    loader = Loader(max_acceleration=1e6)
    env = gym.make(MAIN_ID, loader=loader, start_pose=(path.x[0], path.z[0], path.blade_angle[0]),
                   start_noise=(0.0, 0.0, 0.0), max_tilt_acceleration=1e6, sensor_noise=0.0)
    env.reset(seed=0)
    for a in path_actions(path, loader):
        _, _, terminated, _, _ = env.step(a)
        if terminated:
            break
    rec = env.unwrapped.episode_record()
    n = len(rec["x"])
    np.testing.assert_allclose(rec["x"], path.x[:n], atol=1e-6)
    np.testing.assert_allclose(rec["z"], path.z[:n], atol=1e-6)
    np.testing.assert_allclose(rec["blade_angle"], path.blade_angle[:n], atol=1e-6)


def test_tracker_rejects_bad_input():
    with pytest.raises(ParameterError, match="BucketPath"):
        PathTracker([0.0, 1.0])
    with pytest.raises(ParameterError, match="control_rate"):
        PathTracker(default_path(), control_rate=0.0)


def _resultant_rmse(a_t, a_n, b_t, b_n) -> float:
    return float(np.sqrt(np.mean((np.hypot(a_t, a_n) - np.hypot(b_t, b_n)) ** 2)))


@pytest.mark.parametrize("soil", ["gravel", "dirt"])
def test_scripted_cycle_calibrates_back_to_the_hidden_soil(soil):
    calibration = pytest.importorskip("wheelloader.estimator.calibration")
    if not hasattr(calibration, "calibrate"):
        pytest.skip("wheelloader.estimator.calibration.calibrate not available yet")
    env = gym.make(MAIN_ID, soil=soil)
    run_path(env, seed=0)
    log = env.unwrapped.last_cycle_log()
    rec = env.unwrapped.episode_record()
    result = calibration.calibrate(log)
    model = soil_forces(result.params, log.contact_state(), log.bucket)
    fit = _resultant_rmse(model.tangential, model.normal, log.tangential, log.normal)
    floor = _resultant_rmse(rec["true_F_T"], rec["true_F_N"], log.tangential, log.normal)
    assert fit <= 1.2 * floor, (fit, floor)
    # the identified parameters reproduce the true (noise-free) forces far below the noise level
    truth = soil_forces(preset(soil), log.contact_state(), log.bucket)
    assert _resultant_rmse(model.tangential, model.normal, truth.tangential, truth.normal) < floor
