"""Rendering speed of the bucket-loading env: rgb_array frames per second at 640 x 360.

Runs one cycle of ``wheelloader/BucketLoading-v0`` (the paper's Bezier path tracked by
:class:`~wheelloader.envs.scripted.PathTracker`), renders after every step and times ``env.render()``
alone; the first frame (which builds the figure and its kept background) is reported apart. Repeats the
cycle ``--repeats`` times and reports the best repeat's median (and p90) time per frame. Writes
``render_speed.json`` (with machine, versions, git commit and load average) and ``render_frame.png``, the
frame at ``--frame-time`` seconds into the cycle (the README's ``docs/env_frame.png`` is this frame).

Usage: ``python benchmarks/render_speed.py [--out results/render_speed] [--repeats 3] [--frame-time 2.5]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from wheelloader.provenance import machine_info

#: Target frames per second of rgb_array rendering at 640 x 360.
TARGET_FPS = 20.0


def render_cycle(seed: int) -> tuple[list[float], float, np.ndarray, list[np.ndarray]]:
    """Seconds per ``render()`` call over one scripted cycle (first frame excluded), the first frame's seconds,
    the frame shape and every frame."""
    import gymnasium as gym

    import wheelloader.envs  # noqa: F401 - registers the env ids
    from wheelloader.envs.config import pile_toe
    from wheelloader.envs.scripted import PathTracker
    from wheelloader.estimator import default_path

    env = gym.make("wheelloader/BucketLoading-v0", soil="gravel", render_mode="rgb_array")
    base = env.unwrapped
    obs, _ = env.reset(seed=seed)
    tracker = PathTracker(default_path(pile_toe(base.cfg.pile), rate=base.cfg.control_rate), base.cfg.loader,
                          base.cfg.control_rate)
    tic = time.perf_counter()
    frames = [env.render()]
    first = time.perf_counter() - tic
    times = []
    for _ in range(2000):
        obs, _, terminated, truncated, _ = env.step(tracker(obs))
        tic = time.perf_counter()
        frames.append(env.render())
        times.append(time.perf_counter() - tic)
        if terminated or truncated:
            break
    env.close()
    return times, first, frames[0].shape, frames


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/render_speed", help="output directory (default: %(default)s)")
    parser.add_argument("--repeats", type=int, default=3, help="cycles rendered; the best is reported")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frame-time", type=float, default=2.5, help="time of the saved frame [s]")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    load_start = machine_info()["loadavg_1_5_15min"]
    runs = []
    frames: list[np.ndarray] = []
    for _ in range(args.repeats):
        times, first, shape, frames = render_cycle(args.seed)
        runs.append({"frames": len(times), "median_s": statistics.median(times),
                     "p90_s": float(np.percentile(times, 90)), "mean_s": statistics.fmean(times), "first_s": first})
    best = min(runs, key=lambda r: r["median_s"])
    fps = 1.0 / best["median_s"]
    results = {
        "benchmark": "render_speed", "env": "wheelloader/BucketLoading-v0", "render_mode": "rgb_array",
        "frame_shape": list(shape), "repeats": args.repeats, "runs": runs,
        "frames_per_second_median": fps, "frames_per_second_p90": 1.0 / best["p90_s"],
        "first_frame_s": best["first_s"], "target_fps": TARGET_FPS, "meets_target": fps >= TARGET_FPS,
        "machine": machine_info(), "loadavg_at_start": load_start,
    }
    (out / "render_speed.json").write_text(json.dumps(results, indent=2))
    index = min(len(frames) - 1, max(0, round(args.frame_time * 60.0)))
    import matplotlib.image as mpimg

    mpimg.imsave(out / "render_frame.png", frames[index])
    print(f"rgb_array {shape[1]}x{shape[0]}: {fps:.1f} frames/s (median {1e3 * best['median_s']:.1f} ms, "
          f"p90 {1e3 * best['p90_s']:.1f} ms per frame over {best['frames']} frames; first frame "
          f"{1e3 * best['first_s']:.0f} ms); target {TARGET_FPS:g}: {'met' if results['meets_target'] else 'NOT met'}")
    print(f"load average at start {load_start}, at end {results['machine']['loadavg_1_5_15min']}")
    print(f"wrote {out / 'render_speed.json'} and {out / 'render_frame.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
