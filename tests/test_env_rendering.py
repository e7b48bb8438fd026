"""The env's rgb_array frames: right shape, they follow the state, and a frame depends only on the state
(the renderer keeps its figure and artists between frames, so nothing may linger from an earlier one)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

import wheelloader.envs  # noqa: F401 - registers the env ids
from wheelloader.envs.config import pile_toe
from wheelloader.envs.rendering import EnvRenderer
from wheelloader.envs.scripted import PathTracker
from wheelloader.estimator import Pile, default_path


def _dig(steps: int, seed: int = 0, **kwargs):
    """An env with render_mode rgb_array after ``steps`` tracked steps, and the frames rendered on the way."""
    env = gym.make("wheelloader/BucketLoading-v0", render_mode="rgb_array", **kwargs)
    base = env.unwrapped
    obs, _ = env.reset(seed=seed)
    tracker = PathTracker(default_path(pile_toe(base.cfg.pile), rate=base.cfg.control_rate), base.cfg.loader,
                          base.cfg.control_rate)
    frames = [env.render()]
    for _ in range(steps):
        obs, *_ = env.step(tracker(obs))
        frames.append(env.render())
    return env, frames


def test_frames_have_the_size_and_follow_the_state():
    env, frames = _dig(150)
    assert all(f.shape == (360, 640, 3) and f.dtype == np.uint8 for f in frames)
    changed = [not np.array_equal(a, b) for a, b in zip(frames[:-1], frames[1:], strict=True)]
    assert all(changed), "every step changes the frame (at least its time and forces)"
    scene = [f[60:, :450] for f in frames[::10]]  # below the title, left of the force values: the bucket moves
    assert all(not np.array_equal(a, b) for a, b in zip(scene[:-1], scene[1:], strict=True))
    # the soil colour grows inside the bucket as it fills, the arrows' colours appear once the blade is in soil
    red = np.all(frames[-1] == (214, 39, 40), axis=-1).sum()
    blue = np.all(frames[-1] == (31, 119, 180), axis=-1).sum()
    assert red > 20 and blue > 20
    assert np.all(frames[0] == (214, 39, 40), axis=-1).sum() < red
    env.close()


def test_a_frame_depends_only_on_the_state():
    env, frames = _dig(120)
    again = env.render()
    np.testing.assert_array_equal(again, frames[-1])  # rendering twice: the same picture
    # a fresh renderer (figure built from scratch) draws the same picture of the same state: nothing from the
    # 120 frames before lingers in the kept one
    fresh = EnvRenderer("rgb_array", env.unwrapped.cfg).draw(env.unwrapped.render_state())
    np.testing.assert_array_equal(fresh, frames[-1])
    # the same seed and actions in another env: the same frames
    other, frames_b = _dig(120)
    for a, b in zip(frames[::20], frames_b[::20], strict=True):
        np.testing.assert_array_equal(a, b)
    env.close()
    other.close()


def test_a_new_pile_rebuilds_the_scene():
    renderer = EnvRenderer("rgb_array", gym.make("wheelloader/BucketLoading-v0").unwrapped.cfg)
    env_a, _ = _dig(30)
    env_b, _ = _dig(30, pile=Pile.trapezoid(angle=math.radians(20.0)))
    frame_a = renderer.draw(env_a.unwrapped.render_state())
    frame_b = renderer.draw(env_b.unwrapped.render_state())
    assert not np.array_equal(frame_a, frame_b)
    np.testing.assert_array_equal(renderer.draw(env_a.unwrapped.render_state()), frame_a)
