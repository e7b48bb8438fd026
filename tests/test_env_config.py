"""EnvConfig: the one list of env settings (validation, derived values, replace, the envs' signatures)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from wheelloader.envs import BucketLoadingEnv, EnvConfig, RewardTerms, RewardWeights
from wheelloader.envs.bookkeeping import reward_terms
from wheelloader.envs.config import REWARD_TERMS, SETTING_NAMES, nominal_start_pose, pile_toe
from wheelloader.envs.vector import BucketLoadingVectorEnv
from wheelloader.estimator import Bucket, Loader, ParameterError, Pile, preset


def test_defaults_parse_to_objects_and_the_envs_hold_the_same_settings():
    cfg = EnvConfig()
    assert cfg.soil == preset("gravel")
    assert isinstance(cfg.pile, Pile) and isinstance(cfg.loader, Loader) and isinstance(cfg.bucket, Bucket)
    assert cfg.reward_weights == RewardWeights() and cfg.truth.active is False
    assert len(cfg.start_pose) == 3 and all(isinstance(v, float) for v in cfg.start_pose)
    for env_cfg in (BucketLoadingEnv().cfg, BucketLoadingVectorEnv(num_envs=2).cfg):
        for name in SETTING_NAMES:
            mine, theirs = getattr(env_cfg, name), getattr(cfg, name)
            if isinstance(mine, Pile):
                np.testing.assert_array_equal(mine.heights, theirs.heights)
            else:
                assert mine == theirs, name


def test_from_kwargs_names_the_owner_and_the_unknown_setting():
    with pytest.raises(TypeError, match=r"BucketLoadingEnv\(\) got an unexpected keyword argument 'sensor_nois'"):
        EnvConfig.from_kwargs("BucketLoadingEnv", sensor_nois=0.0)
    assert EnvConfig.from_kwargs(sensor_noise=0).sensor_noise == 0.0


@pytest.mark.parametrize(("name", "value", "message"), [
    ("stall_patience", 0, "stall_patience must be an int >= 1, got 0"),
    ("relax_iterations", True, "relax_iterations must be an int >= 1, got True"),
    ("cycles_per_episode", 1.5, "cycles_per_episode must be an int >= 1"),
    ("control_rate", 0.0, "control_rate must be in (0, inf), got 0.0"),
    ("sensor_noise", -1.0, "sensor_noise must be in [0, inf), got -1.0"),
    ("sensor_noise", math.nan, "sensor_noise must be a finite number, got nan"),
    ("exit_min_fill", 1.5, "exit_min_fill must be in [0, 1], got 1.5"),
    ("start_noise", (0.1, -0.1, 0.0), "start_noise[1] must be in [0, inf)"),
    ("start_pose", (1.0, 2.0), "start_pose must be an (x [m], z [m], blade_angle [rad]) triple"),
    ("blade_angle_limits", (0.5, 0.2), "blade_angle_limits[1] must be in (0.5, 1.5708)"),
    ("lookahead", (0.1, math.inf), "lookahead[1] must be a finite number"),
    ("keep_pile", "yes", "keep_pile must be a bool"),
    ("relax", 2.0, "relax must be a bool or a repose angle"),
])
def test_bad_settings_raise_one_line_naming_the_setting(name, value, message):
    with pytest.raises(ParameterError) as info:
        EnvConfig(**{name: value})
    assert message in str(info.value) and "\n" not in str(info.value)


def test_replace_validates_again_and_derived_values_follow():
    cfg = EnvConfig(control_rate=50.0)
    assert cfg.dt == pytest.approx(0.02) and cfg.speed_step == pytest.approx(cfg.loader.max_acceleration * 0.02)
    same = dataclasses.replace(cfg)
    assert same.start_pose == cfg.start_pose and same.soil == cfg.soil and same.dt == cfg.dt
    faster = dataclasses.replace(cfg, control_rate=100.0)
    assert faster.dt == pytest.approx(0.01) and faster.tilt_rate_step == pytest.approx(faster.max_tilt_acceleration
                                                                                      * 0.01)
    assert cfg.dt == pytest.approx(0.02)  # the cached value of the original is its own
    with pytest.raises(ParameterError, match="control_rate"):
        dataclasses.replace(cfg, control_rate=-1.0)
    cfg = EnvConfig(exit_min_fill=0.25, truth={"stone_rate": 1.0, "stone_duration": 0.1})
    assert cfg.exit_fill_volume == pytest.approx(0.25 * cfg.bucket.capacity)
    assert cfg.stone_decay == pytest.approx(math.exp(-cfg.dt / 0.1))
    low, high = cfg.observation_limits
    np.testing.assert_array_equal(low, cfg.obs_bounds()[0])
    np.testing.assert_array_equal(high, cfg.obs_bounds()[1])
    assert low.dtype == np.float32 and not low.flags.writeable and cfg.observation_limits[0] is low


def test_reward_terms_are_named_and_sum_in_order():
    terms = reward_terms(RewardWeights(), 1.2, 2e4, 2.5e4, 0.1, 500.0, True, False, 1.7e4, 1e3)
    assert isinstance(terms, RewardTerms)
    assert terms.fill == pytest.approx(0.1 / 1.2) and terms.validity == -0.01 and terms.stall == 0.0
    assert terms.total() == terms[0] + terms[1] + terms[2] + terms[3] + terms[4]
    assert REWARD_TERMS == tuple("reward_" + name for name in RewardTerms._fields)


def test_nominal_start_pose_clears_a_carved_floor_that_dips_below_its_first_node():
    # a plant's carved surface: a few mm of spill at the first node, a dip of one grid cell further on, then the
    # face; the old rule started the tip at min + 0.03 m = 0.0 m, inside the spill, with the blade flat to it
    fresh = Pile.trapezoid()
    x = np.asarray(fresh.x)
    z = np.where(x < 0.1, 0.0, np.asarray(fresh.heights))
    z[0] = 0.005
    z[(x > -0.4) & (x < 0.0)] = -0.03
    carved = Pile.from_polyline(x, z)
    x0, z0, blade = nominal_start_pose(carved)
    assert x0 <= carved.x0
    assert z0 == pytest.approx(0.005 + 0.03)
    assert z0 > carved.height_at(x0) + 0.02
    assert blade == pytest.approx(math.radians(-5.0))
    # a pile whose lowest ground is in front of the face keeps the old start (min + 0.03 m, 0.10 m before the toe)
    assert nominal_start_pose(fresh) == pytest.approx((pile_toe(fresh) - 0.10, float(fresh.heights.min()) + 0.03,
                                                       math.radians(-5.0)))
