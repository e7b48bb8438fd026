"""RLlib PPO speed: env-steps/s with 1 and 2 env runners (same PPO settings as ``rllib_ppo.py``).

For each ``--runners`` count one PPO algorithm is built in the same Ray session and trained for
``--iterations`` iterations of ``--train-batch`` env-steps (the first is dropped as warm-up). Reported per
count: sampling env-steps/s (env-steps / time in ``sample``, all runners together), end-to-end env-steps/s
(env-steps / iteration wall time, learner update included), the learner's share of the iteration time,
and the machine's load average before and after. Writes ``rllib_speed.json`` into ``--out``.

Usage::

    python train/rllib_speed.py --runners 1 2 --iterations 4 --out results/rllib_speed
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from common import machine_info, set_torch_threads, write_json
from rllib_ppo import add_rllib_args, build_config, iteration_record, start_ray


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, measure, write ``rllib_speed.json``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_rllib_args(parser)
    parser.add_argument("--runners", type=int, nargs="+", default=[1, 2], help="env-runner counts to compare")
    parser.add_argument("--iterations", type=int, default=4, help="train iterations per count (first = warm-up)")
    parser.add_argument("--out", type=Path, default=Path("results/rllib_speed"))
    args = parser.parse_args(argv)
    if args.iterations < 2:
        raise SystemExit("--iterations must be >= 2 (the first is a warm-up)")
    import ray

    set_torch_threads(args.torch_threads)
    start_ray(args)
    runs = []
    try:
        for runners in args.runners:
            args.num_env_runners = runners
            load0 = machine_info()["loadavg_1_5_15min"]
            t0 = time.perf_counter()
            algo = build_config(args).build_algo()
            build_s = time.perf_counter() - t0
            records = [iteration_record(algo.train(), k + 1) for k in range(args.iterations)]
            algo.stop()
            timed = records[1:]
            steps = sum(r["env_steps"] for r in timed)
            wall = sum(r["time_s"] for r in timed)
            sampling = sum(r["sampling_s"] or 0.0 for r in timed)
            learner = sum(r["learner_s"] or 0.0 for r in timed)
            run = {"num_env_runners": runners, "num_envs_per_env_runner": args.num_envs_per_env_runner,
                   "vectorize_mode": args.vectorize_mode, "build_s": build_s, "iterations": records,
                   "timed_env_steps": steps, "timed_wall_s": wall,
                   "env_steps_per_s": steps / wall if wall > 0 else None,
                   "sampling_env_steps_per_s": steps / sampling if sampling > 0 else None,
                   "learner_share": learner / wall if wall > 0 else None,
                   "iteration_s_median": statistics.median(r["time_s"] for r in timed),
                   "loadavg_before": load0, "loadavg_after": machine_info()["loadavg_1_5_15min"]}
            runs.append(run)
            print(f"{runners} env runner(s): {run['env_steps_per_s']:.0f} env-steps/s end to end, sampling "
                  f"{run['sampling_env_steps_per_s']:.0f} env-steps/s, learner {run['learner_share']:.0%} of the "
                  f"iteration; build {build_s:.0f} s; load {load0} -> {run['loadavg_after']}", flush=True)
    finally:
        ray.shutdown()
    report = {"benchmark": "rllib_speed", "settings": {k: v for k, v in vars(args).items() if k != "out"},
              "runs": runs, "machine": machine_info()}
    write_json(args.out / "rllib_speed.json", report)
    print(f"wrote {args.out / 'rllib_speed.json'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
