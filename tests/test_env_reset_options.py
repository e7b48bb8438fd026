"""One parser of reset options for the single and the batched env (#13 item 3): same accepted values,
same rejected values, same messages."""

from __future__ import annotations

import math
import re

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs.bookkeeping import RESET_OPTIONS, parse_reset_options
from wheelloader.envs.config import EnvConfig
from wheelloader.envs.vector import BucketLoadingVectorEnv
from wheelloader.estimator import preset
from wheelloader.estimator.errors import ParameterError

MAIN_ID = "wheelloader/BucketLoading-v0"

#: Every reset option with values that must be rejected.
BAD_OPTIONS = [
    ("sensor_noise", float("nan")), ("sensor_noise", -1.0), ("sensor_noise", -1), ("sensor_noise", math.inf),
    ("sensor_noise", "150"), ("sensor_noise", True), ("sensor_noise", None),
    ("relax", -1.0), ("relax", -1), ("relax", "yes"), ("relax", 3.0), ("relax", 0.0), ("relax", math.nan),
    ("relax", None),
    ("keep_pile", "no"), ("keep_pile", 1), ("keep_pile", None),
    ("soil", "granite"), ("soil", 42), ("soil", {"phi": -1.0}),
    ("truth", {"rocks": 1.0}), ("truth", {"compaction": -1.0}), ("truth", 3),
    ("keep_piles", True), ("reset_mask", np.ones(2, dtype=bool)),
]

#: Every reset option with values that must be accepted.
GOOD_OPTIONS = [
    ("sensor_noise", 0.0), ("sensor_noise", 300), ("sensor_noise", np.float32(10.0)),
    ("relax", True), ("relax", False), ("relax", 0.5), ("relax", np.float64(0.4)), ("relax", np.True_),
    ("keep_pile", True), ("keep_pile", False), ("keep_pile", np.bool_(True)),
    ("soil", "keep"), ("soil", "resample"), ("soil", "lean_clay"), ("soil", preset("sand")),
    ("soil", preset("dirt").to_dict()),
    ("truth", None), ("truth", {"compaction": 0.5}),
]


def _error(env, options) -> str:
    with pytest.raises(ParameterError) as info:
        env.reset(seed=0, options=options)
    return str(info.value)


def test_every_reset_option_is_covered():
    assert {k for k, _ in BAD_OPTIONS} >= set(RESET_OPTIONS)
    assert {k for k, _ in GOOD_OPTIONS} == set(RESET_OPTIONS)


@pytest.mark.parametrize(("key", "value"), BAD_OPTIONS, ids=[f"{k}={v!r}" for k, v in BAD_OPTIONS])
def test_single_and_vector_env_reject_the_same_options_with_the_same_message(key, value):
    single = gym.make(MAIN_ID).unwrapped
    vector = BucketLoadingVectorEnv(num_envs=2)
    if key == "reset_mask":  # the batched env's own option: the single env does not know it
        assert "unknown key(s) ['reset_mask']" in _error(single, {key: value})
        vector.reset(seed=0, options={key: value})
        return
    message = _error(single, {key: value})
    assert message == _error(vector, {key: value})
    assert key in message or "truth" in message or "TruthOptions" in message  # names the bad option
    if key in ("sensor_noise", "relax", "keep_pile"):
        assert repr(value) in message or str(value) in message  # and the bad value


@pytest.mark.parametrize(("key", "value"), GOOD_OPTIONS, ids=[f"{k}={v!r}" for k, v in GOOD_OPTIONS])
def test_single_and_vector_env_accept_the_same_options_alike(key, value):
    """An accepted option gives the same first observation in both envs (same seed)."""
    single = gym.make(MAIN_ID)
    vector = BucketLoadingVectorEnv(num_envs=2)
    single.reset(seed=3)
    vector.reset(seed=[3, 4])
    obs_s, info_s = single.reset(seed=3, options={key: value})
    obs_v, info_v = vector.reset(seed=[3, 4], options={key: value})
    np.testing.assert_allclose(obs_s, obs_v[0], rtol=1e-6, atol=1e-6)
    assert info_s["soil"] == {k: v[0] for k, v in info_v["soil"].items() if not k.startswith("_")}
    assert np.all(np.isfinite(obs_v))


def test_nan_sensor_noise_no_longer_poisons_the_batched_observations():
    """The audit's reproduction: make_vec(...).reset(options={"sensor_noise": nan}) gave NaN observations."""
    envs = gym.make_vec(MAIN_ID, num_envs=2)
    with pytest.raises(ParameterError, match=re.escape("reset option sensor_noise must be a finite number")):
        envs.reset(options={"sensor_noise": float("nan")})
    obs, _ = envs.reset(seed=0)
    for _ in range(5):
        obs, *_ = envs.step(envs.action_space.sample())
    assert np.all(np.isfinite(obs))


def test_a_rejected_reset_leaves_the_env_as_it_was():
    env = gym.make(MAIN_ID).unwrapped
    env.reset(seed=1)
    before = env.render_state()
    with pytest.raises(ParameterError):
        env.reset(seed=5, options={"relax": "yes"})
    assert env.render_state()["x"] == before["x"]
    assert env.cfg.sensor_noise == 150.0


def test_parser_returns_settings_and_keeps_the_config_unless_changed():
    cfg = EnvConfig(keep_pile=True, relax=0.4)
    req = parse_reset_options(None, cfg)
    assert (req.keep_pile, req.relax, req.soil, req.config_changed) == (True, 0.4, None, False)
    assert req.config is cfg
    req = parse_reset_options({"sensor_noise": 20, "relax": False, "soil": "sand"}, cfg)
    assert req.config.sensor_noise == 20.0 and req.relax is False and req.soil == preset("sand")
    assert req.config_changed and cfg.sensor_noise == 150.0
    with pytest.raises(ParameterError, match="reset options must be a dict"):
        parse_reset_options([("relax", True)], cfg)


def test_constructor_relax_is_validated_like_the_reset_option():
    for bad in (-1.0, "yes", 3.0, math.nan):
        with pytest.raises(ParameterError, match="relax must be a bool or a repose angle"):
            gym.make(MAIN_ID, relax=bad)
