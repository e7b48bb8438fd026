"""Train PPO with RLlib (Ray) on the batched bucket-loading env, by env id, and evaluate it like the SB3 baseline.

The env is given by id, ``"wheelloader.envs:wheelloader/BucketLoading-v0"`` (the module prefix makes
every RLlib env-runner process import ``wheelloader.envs`` and so find the id), and each env runner
builds the NumPy-batched vector env through ``gym_env_vectorize_mode="vector_entry_point"`` (one
``BucketLoadingVectorEnv`` of ``--num-envs-per-env-runner`` sub-envs per runner). The defaults mirror
``train/ppo.py`` where RLlib has the same knob: 16 sub-envs (2 runners x 8), 4096 env-steps per update,
minibatch 512, 10 epochs, learning rate 3e-4, gamma 0.995, a 64-64 MLP, hidden soil drawn uniformly from
the presets at every reset (the ``randomized`` set-up). RLlib's PPO has no gSDE (SB3's PPO here uses it).

Writes into ``--out`` (default ``results/rllib_ppo``): ``checkpoint/`` (``Algorithm.save_to_path``; the
policy loads with ``train/policies.py:load_rllib``), ``config.json``, ``train_summary.json`` (per iteration:
env-steps, wall time, sampling and learner time, episode return; env-steps/s, load average), and
``evaluate/`` (``train/evaluate.py`` on the trained policy with the fixed Bezier paths and the random
policy: the SB3 baseline's evaluation, same soils, seeds and metrics).

Install: ``pip install torch==2.13.0 && pip install -e ".[rllib]"``.

Usage::

    python train/rllib_ppo.py --total-timesteps 400000 --out results/rllib_ppo
    python train/rllib_ppo.py --ray auto ...       # on a running Ray cluster (ray start --head / --address)
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path
from typing import Any

from common import int_list, machine_info, set_torch_threads, str_list, write_json

from wheelloader.ray_mode import LOCAL, OFF, parse_ray_mode

#: The env by id, importable in a fresh process (RLlib's env runners).
ENV_ID = "wheelloader.envs:wheelloader/BucketLoading-v0"


def ray_address(text: str) -> str:
    """``--ray``: ``local`` or a cluster address (``auto``, ``ray://HOST:10001``); RLlib needs Ray, so not off."""
    mode = parse_ray_mode(text)
    if mode == OFF:
        raise argparse.ArgumentTypeError("--ray off: RLlib runs on Ray; use 'local' or a cluster address")
    return mode


def add_rllib_args(parser: argparse.ArgumentParser) -> None:
    """The PPO and env-runner settings shared by this script and ``rllib_speed.py``."""
    parser.add_argument("--soil", default="random", help="hidden soil of the training env (default: random preset)")
    parser.add_argument("--num-env-runners", type=int, default=2, help="RLlib env runners (Ray actors, 1 CPU each)")
    parser.add_argument("--num-envs-per-env-runner", type=int, default=8, help="sub-envs per runner's batched env")
    parser.add_argument("--vectorize-mode", choices=("vector_entry_point", "sync"), default="vector_entry_point",
                        help="the NumPy-batched env (default) or Gymnasium's SyncVectorEnv of single envs")
    parser.add_argument("--train-batch", type=int, default=4096, help="env-steps per PPO update")
    parser.add_argument("--minibatch-size", type=int, default=512)
    parser.add_argument("--num-epochs", type=int, default=10)
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--gamma", type=float, default=0.995)
    parser.add_argument("--net-arch", type=int, nargs="+", default=[64, 64], help="hidden layer sizes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--torch-threads", type=int, default=1, help="torch threads of the learner (default 1)")
    parser.add_argument("--ray", type=ray_address, default=LOCAL, metavar="MODE",
                        help="'local' (ray.init() on this machine, default) or a cluster: 'auto', 'ray://HOST:10001'")
    parser.add_argument("--ray-cpus", type=int, default=None, help="with --ray local: CPUs Ray may use")


def build_config(args: argparse.Namespace) -> Any:
    """The RLlib ``PPOConfig`` of the parsed arguments."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig

    if args.num_env_runners < 0 or args.num_envs_per_env_runner < 1:
        raise SystemExit("--num-env-runners must be >= 0 and --num-envs-per-env-runner >= 1")
    collectors = max(args.num_env_runners, 1) * args.num_envs_per_env_runner
    fragment = max(args.train_batch // collectors, 1)
    return (PPOConfig()
            .environment(ENV_ID, env_config={"soil": args.soil})
            .env_runners(num_env_runners=args.num_env_runners, num_envs_per_env_runner=args.num_envs_per_env_runner,
                         gym_env_vectorize_mode=args.vectorize_mode, rollout_fragment_length=fragment)
            .training(train_batch_size_per_learner=fragment * collectors, minibatch_size=args.minibatch_size,
                      num_epochs=args.num_epochs, lr=args.learning_rate, gamma=args.gamma)
            .rl_module(model_config=DefaultModelConfig(fcnet_hiddens=list(args.net_arch), vf_share_layers=False))
            .debugging(seed=args.seed))


def start_ray(args: argparse.Namespace) -> None:
    """``ray.init`` for ``--ray`` (one BLAS/torch thread per worker unless the user chose otherwise)."""
    import ray

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")  # inherited by the env-runner processes
    if args.ray == LOCAL:
        ray.init(num_cpus=args.ray_cpus, include_dashboard=False)
    else:
        ray.init(address=args.ray)


def iteration_record(result: dict[str, Any], k: int) -> dict[str, Any]:
    """What one ``Algorithm.train()`` result says about speed and learning."""
    runners = result.get("env_runners", {})
    timers = result.get("timers", {})
    return {"iteration": k, "env_steps": int(runners.get("num_env_steps_sampled", 0)),
            "env_steps_lifetime": int(result.get("num_env_steps_sampled_lifetime", 0)),
            "time_s": float(result.get("time_this_iter_s", 0.0)),
            "sampling_s": timers.get("env_runner_sampling_timer"), "learner_s": timers.get("learner_update_timer"),
            "episode_return_mean": runners.get("episode_return_mean"),
            "episode_len_mean": runners.get("episode_len_mean"), "episodes": runners.get("num_episodes")}


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_rllib_args(parser)
    parser.add_argument("--total-timesteps", type=int, default=400_000, help="env-steps to train")
    parser.add_argument("--out", type=Path, default=Path("results/rllib_ppo"), help="output directory")
    parser.add_argument("--eval", action=argparse.BooleanOptionalAction, default=True,
                        help="evaluate the trained policy with train/evaluate.py (default on)")
    parser.add_argument("--eval-soils", type=str_list, default="all", help="evaluation soils ('all' = presets)")
    parser.add_argument("--eval-seeds", type=int_list, default="2000-2004", help="evaluation env seeds")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, train, save, evaluate."""
    args = build_parser().parse_args(argv)
    if args.total_timesteps < 1:
        raise SystemExit(f"--total-timesteps must be >= 1, got {args.total_timesteps}")
    import ray

    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    threads = set_torch_threads(args.torch_threads)
    start_ray(args)
    try:
        config = build_config(args)
        write_json(out / "config.json", {"algo": "rllib ppo", "env_id": ENV_ID, "args": vars(args),
                                         "train_batch": config.train_batch_size_per_learner,
                                         "rollout_fragment_length": config.rollout_fragment_length,
                                         "torch_threads": threads, "machine": machine_info()})
        t_build = time.perf_counter()
        algo = config.build_algo()
        build_s = time.perf_counter() - t_build
        load0 = machine_info()["loadavg_1_5_15min"]
        iterations: list[dict[str, Any]] = []
        t0 = time.perf_counter()
        steps = 0
        while steps < args.total_timesteps:
            record = iteration_record(algo.train(), len(iterations) + 1)
            iterations.append(record)
            steps = record["env_steps_lifetime"]
            print(f"iteration {record['iteration']:4d}: {steps:8d} env-steps, {record['time_s']:5.1f} s, "
                  f"episode return {record['episode_return_mean']}", flush=True)
        wall = time.perf_counter() - t0
        checkpoint = Path(algo.save_to_path(str((out / "checkpoint").resolve())))
        algo.stop()
    finally:
        ray.shutdown()
    summary = {"algo": "rllib ppo", "env_id": ENV_ID, "vectorize_mode": args.vectorize_mode,
               "num_env_runners": args.num_env_runners, "num_envs_per_env_runner": args.num_envs_per_env_runner,
               "timesteps": steps, "iterations": iterations, "build_s": build_s, "wall_s": wall,
               "env_steps_per_s": steps / wall, "loadavg_before": load0,
               "loadavg_after": machine_info()["loadavg_1_5_15min"], "checkpoint": str(checkpoint)}
    write_json(out / "train_summary.json", summary)
    print(f"RLlib PPO: {steps} env-steps in {wall:.1f} s ({steps / wall:.0f} env-steps/s, algorithm build "
          f"{build_s:.0f} s); checkpoint -> {checkpoint}", flush=True)
    if args.eval:
        import evaluate

        evaluate.main(["--rllib", str(checkpoint), "--soils", ",".join(args.eval_soils), "--seeds",
                       ",".join(map(str, args.eval_seeds)), "--no-mpc", "--torch-threads", str(args.torch_threads),
                       "--out", str(out / "evaluate")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
