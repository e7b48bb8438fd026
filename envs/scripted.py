"""Scripted policies: follow a bucket path (e.g. the paper's Bezier path) in the env.

:class:`PathTracker` turns a :class:`~wheelloader.estimator.BucketPath` into
normalised env actions: feed-forward velocity of the path plus proportional
feedback on the tip pose read from the observation (indices 0-2: x, z,
blade angle). :func:`path_actions` gives the open-loop actions, and
:func:`run_path` runs one cycle with a tracker.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, Loader, ParameterError, default_path
from wheelloader.estimator.checks import check_range


class PathTracker:
    """Closed-loop tracking of a bucket path with the env's normalised actions.

    Parameters
    ----------
    path : BucketPath
        Path to follow (time from its first sample).
    loader : Loader
        Machine limits used to normalise the commands (must match the env's).
    control_rate : float
        Env control rate [Hz].
    gain : float
        Position feedback gain [1/s] on x and z.
    angle_gain : float
        Blade-angle feedback gain [1/s].
    """

    def __init__(self, path: BucketPath, loader: Loader | None = None, control_rate: float = 60.0,
                 gain: float = 4.0, angle_gain: float = 4.0) -> None:
        if not isinstance(path, BucketPath):
            raise ParameterError(f"path must be a BucketPath, got {type(path).__name__}")
        control_rate = check_range("control_rate [Hz]", control_rate, 0.0, low_open=True)
        self.path = path
        self.loader = loader or Loader()
        self.dt = 1.0 / float(control_rate)
        self.gain, self.angle_gain = float(gain), float(angle_gain)
        self._t = path.t - path.t[0]
        self.step_index = 0

    def reset(self) -> None:
        """Restart from the beginning of the path."""
        self.step_index = 0

    def target(self, time: float) -> tuple[float, float, float]:
        """Path pose (x, z, blade angle) at ``time`` [s] from the path start (held at the end)."""
        p = self.path
        return (float(np.interp(time, self._t, p.x)), float(np.interp(time, self._t, p.z)),
                float(np.interp(time, self._t, p.blade_angle)))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Action for the current observation; advances the tracker's clock by one step."""
        k = self.step_index
        self.step_index += 1
        now = self.target(k * self.dt)
        nxt = self.target((k + 1) * self.dt)
        x, z, th = float(obs[0]), float(obs[1]), float(obs[2])
        vx = (nxt[0] - now[0]) / self.dt + self.gain * (nxt[0] - x)
        vz = (nxt[1] - now[1]) / self.dt + self.gain * (nxt[1] - z)
        om = (nxt[2] - now[2]) / self.dt + self.angle_gain * (nxt[2] - th)
        ld = self.loader
        act = np.array([vx / ld.max_speed, vz / ld.max_speed, om / ld.max_tilt_rate])
        return np.clip(act, -1.0, 1.0).astype(np.float32)


def path_actions(path: BucketPath, loader: Loader | None = None) -> np.ndarray:
    """Open-loop normalised actions ``(len(path) - 1, 3)`` that reproduce ``path`` when the env starts
    at its first pose, runs at the path's rate and no rate limit is hit."""
    ld = loader or Loader()
    dt = np.diff(path.t)
    act = np.column_stack([np.diff(path.x) / dt / ld.max_speed, np.diff(path.z) / dt / ld.max_speed,
                           np.diff(path.blade_angle) / dt / ld.max_tilt_rate])
    return np.clip(act, -1.0, 1.0).astype(np.float32)


def run_path(env: Any, path: BucketPath | None = None, *, seed: int | None = None,
             options: dict[str, Any] | None = None, max_steps: int = 2000) -> dict[str, Any]:
    """Run one cycle of ``env`` with a :class:`PathTracker` on ``path`` (default: the paper's Bezier path
    on the env's pile toe). Returns totals: ``reward``, ``steps``, ``fill_fraction``, ``terminated``,
    ``stalled``, and the last ``info``."""
    base = env.unwrapped
    if path is None:
        from .config import pile_toe

        path = default_path(pile_toe(base.cfg.pile), rate=base.cfg.control_rate)
    tracker = PathTracker(path, base.cfg.loader, base.cfg.control_rate)
    obs, info = env.reset(seed=seed, options=options)
    total, steps, terminated, truncated = 0.0, 0, False, False
    while steps < max_steps:
        obs, reward, terminated, truncated, info = env.step(tracker(obs))
        total += float(reward)
        steps += 1
        if terminated or truncated:
            break
    return {"reward": total, "steps": steps, "fill_fraction": float(info.get("fill_fraction", np.nan)),
            "terminated": bool(terminated), "truncated": bool(truncated), "stalled": bool(info.get("stalled")),
            "info": info}
