"""The NumPy-batched vector env reproduces the single env (same seeds and actions)."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs.vector import BucketLoadingVectorEnv
from wheelloader.estimator.errors import ParameterError

MAIN_ID = "wheelloader/BucketLoading-v0"

_CONFIGS = [
    {},
    {"soil": "random", "truth": {"compaction": 0.5, "rate_resistance": 1e4, "stone_rate": 3.0, "drift": 0.05},
     "keep_pile": True, "relax": True, "relax_iterations": 50},
    {"soil": {"phi": (0.4, 0.7), "base": "dirt"}, "loader": {"max_push_force": 1500.0}, "stall_patience": 3},
    {"exit_min_fill": 0.05, "keep_pile": True},
    {"force_model": "fee-payload", "soil": "dirt", "loader": {"max_push_force": 1500.0}, "stall_patience": 3},
    {"force_model": "fee-payload", "payload": {"retention": 0.7, "heap_factor": 0.4, "sharpness": 3.0},
     "soil": "random", "truth": {"stone_rate": 3.0}, "keep_pile": True},
    {"force_model": "fee-payload-depth", "soil": "dirt", "loader": {"max_push_force": 1500.0}, "stall_patience": 3},
    {"force_model": "fee-payload", "soil": "dirt",
     "payload": {"retention": 0.8, "heap_factor": 0.45, "sharpness": 2.5, "curl_gain": 0.3},
     "loader": {"max_push_force": 1500.0}, "stall_patience": 3},
    {"force_model": "fee-learned", "soil": "dirt", "loader": {"max_push_force": 900.0}, "stall_patience": 3},
    {"force_model": "fee-learned", "soil": "random", "truth": {"stone_rate": 3.0}, "keep_pile": True},
]


def _compare(config: dict, num_envs: int = 4, steps: int = 300, seed: int = 5, max_steps: int = 100) -> dict:
    vec = BucketLoadingVectorEnv(num_envs=num_envs, max_episode_steps=max_steps, **config)
    singles = [gym.make(MAIN_ID, max_episode_steps=max_steps, **config) for _ in range(num_envs)]
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1, 1, (steps, num_envs, 3)).astype(np.float32)
    acts[:, :, 0] = np.abs(acts[:, :, 0])
    lift = (np.arange(steps) % 60) >= 30  # dig, then lift out: episodes end by exit, stall and time limit
    acts[lift, :, 1] = np.abs(acts[lift, :, 1])
    obs_v, _ = vec.reset(seed=seed)
    for i, env in enumerate(singles):
        np.testing.assert_allclose(env.reset(seed=seed + i)[0], obs_v[i], rtol=1e-6, atol=1e-6)
    done = [False] * num_envs
    counts = {"resets": 0, "stalls": 0, "terminations": 0, "truncations": 0}
    for t in range(steps):
        obs_v, rew_v, term_v, trunc_v, info_v = vec.step(acts[t])
        for i, env in enumerate(singles):
            if done[i]:
                obs, _ = env.reset()
                reward, term, trunc = 0.0, False, False
                counts["resets"] += 1
            else:
                obs, reward, term, trunc, info = env.step(acts[t, i])
                counts["stalls"] += int(info["stalled"])
                for key in ("reward_fill", "reward_energy", "reward_force"):
                    assert info[key] == pytest.approx(info_v[key][i], rel=1e-7, abs=1e-9)
            done[i] = term or trunc
            counts["terminations"] += int(term)
            counts["truncations"] += int(trunc)
            np.testing.assert_allclose(obs, obs_v[i], rtol=1e-6, atol=1e-6, err_msg=f"step {t} env {i}")
            assert reward == pytest.approx(rew_v[i], rel=1e-7, abs=1e-9)
            assert (term, trunc) == (bool(term_v[i]), bool(trunc_v[i]))
    return counts


@pytest.mark.parametrize("config", _CONFIGS)
def test_vector_env_matches_single_envs(config):
    counts = _compare(config)
    assert counts["resets"] > 0
    if "exit_min_fill" not in config:
        # random digging rarely loads 5 % of the bucket: with exit_min_fill the episodes end by time limit
        assert counts["terminations"] > 0
    if "loader" in config:
        assert counts["stalls"] > 0


def test_vector_env_truncates_like_time_limit():
    counts = _compare({"start_pose": (0.5, 1.5, 0.0)}, num_envs=2, steps=60, max_steps=20)
    assert counts["truncations"] > 0


def test_make_vec_uses_the_batched_env():
    envs = gym.make_vec(MAIN_ID, num_envs=8)
    assert isinstance(envs.unwrapped, BucketLoadingVectorEnv)
    assert envs.unwrapped.max_episode_steps == 600
    obs, _ = envs.reset(seed=0)
    assert envs.observation_space.contains(obs)
    for _ in range(50):
        obs, reward, term, trunc, info = envs.step(envs.action_space.sample())
        assert envs.observation_space.contains(obs) and np.all(np.isfinite(reward))
        assert np.array_equal(reward, sum(info[k] for k in wheelloader.envs.REWARD_TERMS))
    clone = pickle.loads(pickle.dumps(envs.unwrapped))
    a = envs.action_space.sample()
    np.testing.assert_array_equal(clone.step(a)[0], envs.step(a)[0])
    envs.close()


# a vector env whose constructor refuses the variant is still closed by gymnasium's __del__: cleanly
@pytest.mark.filterwarnings("error::pytest.PytestUnraisableExceptionWarning")
def test_multi_cycle_variant_falls_back_to_sync_vectorisation():
    envs = gym.make_vec("wheelloader/BucketLoadingMultiCycle-v0", num_envs=2)
    assert not isinstance(envs.unwrapped, BucketLoadingVectorEnv)
    envs.reset(seed=0)
    envs.close()
    with pytest.raises(ParameterError, match="cycles_per_episode"):
        BucketLoadingVectorEnv(num_envs=2, cycles_per_episode=3)


def test_vector_reset_accepts_seed_lists_and_renders():
    vec = BucketLoadingVectorEnv(num_envs=3, render_mode="rgb_array")
    obs_a, _ = vec.reset(seed=[4, 5, 6])
    obs_b, _ = vec.reset(seed=4)
    np.testing.assert_array_equal(obs_a, obs_b)
    frames = vec.render()  # Gymnasium's vector API: one frame per sub-env
    assert isinstance(frames, tuple) and len(frames) == 3
    for frame in frames:
        assert frame.dtype == np.uint8 and frame.ndim == 3
    vec.close()


def test_batched_surfaces_read_the_shared_start_row_only_where_nothing_was_carved():
    """The look-ahead and the carve read a row's own nodes only inside its carved range (elsewhere the shared start
    row): the same heights and the same cuts as reading every row, through carves, undos and a row on another pile."""
    from wheelloader.envs.batched_surface import BatchedSurfaces
    from wheelloader.estimator import Pile, SurfaceCarver

    pile = Pile.trapezoid()
    n = 6
    surf = BatchedSurfaces(pile, n)
    for i in range(n):
        surf.set(i, pile.heights)
    carvers = [SurfaceCarver(pile, 1.0, 10.0) for _ in range(n)]
    rng = np.random.default_rng(2)
    x = rng.uniform(0.2, 1.5, n)
    z = rng.uniform(0.0, 0.6, n)
    for step in range(60):
        if step == 30:  # a row on another pile: every read of it goes to its own row
            other = Pile(pile.x0, pile.spacing, 0.8 * pile.heights)
            surf.set(2, other.heights)
            carvers[2] = SurfaceCarver(other, 1.0, 10.0)
        xn = x + rng.uniform(-0.005, 0.02, n)
        zn = z + rng.uniform(-0.02, 0.01, n)
        idx_u, old_u, area = surf.carve(None, x, z, xn, zn)
        removed = [c.cut_segment(x[i], z[i], xn[i], zn[i]) for i, c in enumerate(carvers)]
        np.testing.assert_array_equal(np.zeros(n) if area is None else area, np.asarray(removed))  # width 1
        if step % 7 == 3 and area is not None:  # undo some rows' cuts (as a stall does)
            surf.undo(idx_u, old_u, np.array([0, 4]))
            for i in (0, 4):
                carvers[i] = SurfaceCarver(surf.pile(i), 1.0, 10.0)
        for i, c in enumerate(carvers):
            np.testing.assert_array_equal(surf.carved[i], c.pile().heights)
        ahead = np.add.outer(np.r_[np.linspace(-0.03, 0.03, 31), 0.1, 0.3, 0.5], xn)  # around the cuts, ahead
        np.testing.assert_array_equal(surf.carved_height(ahead), surf.height(surf.carved, None, ahead))
        x, z = xn, zn
    assert area is not None  # the paths cut
