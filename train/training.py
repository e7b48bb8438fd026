"""The training run shared by ``ppo.py`` and ``sac.py``: command-line arguments and ``train()``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from common import (
    DEFAULT_PLANT_SOIL,
    ENV_ID,
    SETUPS,
    int_list,
    machine_info,
    set_torch_threads,
    str_list,
    weights,
    write_json,
)
from curves import LearningCurveCallback
from setups import VEC_BACKENDS, make_train_env, resolve_setup


def add_training_args(parser: argparse.ArgumentParser, default_steps: int, default_envs: int) -> None:
    """Arguments shared by ppo.py and sac.py."""
    parser.add_argument("--setup", choices=SETUPS, default="randomized",
                        help="randomized: plant with soils drawn from the presets; twin: calibrated digital twin")
    parser.add_argument("--plant-soil", default=DEFAULT_PLANT_SOIL,
                        help=f"hidden soil of the plant cycle for --setup twin (default {DEFAULT_PLANT_SOIL})")
    parser.add_argument("--total-timesteps", type=int, default=default_steps, help="env-steps to train")
    parser.add_argument("--n-envs", type=int, default=default_envs, help="parallel sub-envs")
    parser.add_argument("--vec", choices=VEC_BACKENDS, default="auto",
                        help="auto (default): the faster backend at --n-envs (make_sb3_vec_env's choice: serial single "
                             "envs below wheelloader.envs.sb3.BATCHED_FROM envs, the batched NumPy vector env from "
                             "there; docs/results/env_speed.md); batched; serial; or SB3's DummyVecEnv of single envs")
    parser.add_argument("--seed", type=int, default=0, help="seed of the envs, the policy and the twin's plant cycle")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default results/<algo>_<setup>)")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch intra-op threads (default 1)")
    parser.add_argument("--progress-bar", action=argparse.BooleanOptionalAction, default=True,
                        help="show SB3's progress bar (needs tqdm and rich)")
    parser.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs to OUT/tb")
    parser.add_argument("--checkpoint-freq", type=int, default=100_000,
                        help="save a checkpoint every this many env-steps (0: none)")
    parser.add_argument("--eval-freq", type=int, default=50_000,
                        help="learning-curve evaluation every this many env-steps (0: only start and end)")
    parser.add_argument("--eval-soils", type=str_list, default="gravel,sand,lean_clay,fat_clay",
                        help="soils of the learning-curve evaluation ('all' = every preset)")
    parser.add_argument("--eval-seeds", type=int_list, default="1000-1001",
                        help="env seeds of the learning-curve evaluation (held out from training)")
    parser.add_argument("--init-model", type=Path, default=None,
                        help="start from this saved model (same algorithm), e.g. fine-tune a domain-randomised "
                             "policy on the digital twin; its hyperparameters are kept")
    parser.add_argument("--reward-weights", type=weights, default=None,
                        help="training reward weights, e.g. 'stall=0.2,validity=0.001' (RewardWeights fields; "
                             "default: the env's). Evaluations always use the env's default reward")
    parser.add_argument("--force-model", choices=("fee", "fee-payload"), default="fee",
                        help="the env's force model (EnvConfig.force_model): 'fee-payload' trains with the bucket's "
                             "fill = the payload model's kept soil; the learning-curve evaluation uses the same")
    parser.add_argument("--verbose", type=int, default=0, help="SB3 verbosity")


def train(algo: str, args: argparse.Namespace, model_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Train ``algo`` ("ppo" or "sac") with the parsed ``args``; writes into ``args.out``:

    ``model.zip`` (load with ``PPO.load``/``SAC.load``), ``config.json``,
    ``learning_curve.json``, ``train_summary.json``, ``checkpoints/``,
    ``tb/`` (with ``--tensorboard``), ``plant_cycle.csv`` (twin set-up).
    """
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    if args.total_timesteps < 1:
        raise ValueError(f"--total-timesteps must be >= 1, got {args.total_timesteps!r}")
    out: Path = args.out or Path("results") / f"{algo}_{args.setup}"
    out.mkdir(parents=True, exist_ok=True)
    threads = set_torch_threads(args.torch_threads)
    setup = resolve_setup(args.setup, args.plant_soil, args.seed, out)
    env_kwargs = dict(setup["env_kwargs"])
    if args.reward_weights:
        env_kwargs["reward_weights"] = dict(args.reward_weights)
    model_env = {"force_model": args.force_model} if args.force_model != "fee" else {}
    env_kwargs.update(model_env)
    eval_soils = [args.plant_soil] if args.setup == "twin" else list(args.eval_soils)
    env = make_train_env(env_kwargs, args.n_envs, args.seed, args.vec)
    cls = {"ppo": PPO, "sac": SAC}[algo]
    tb = str(out / "tb") if args.tensorboard else None
    if args.init_model is not None:
        model = cls.load(args.init_model, env=env, device="cpu", verbose=args.verbose, tensorboard_log=tb)
        model.set_random_seed(args.seed)
        model_kwargs = {"init_model": str(args.init_model), "loaded_hyperparameters": True}
    else:
        model = cls("MlpPolicy", env, seed=args.seed, device="cpu", verbose=args.verbose, tensorboard_log=tb,
                    **model_kwargs)
    config = {"algo": algo, "env_id": ENV_ID, "setup": setup["description"], "args": vars(args),
              "env_kwargs": {k: v for k, v in env_kwargs.items() if k != "soil"},
              "vec_env": type(getattr(env, "venv", env)).__name__,  # what --vec resolved to
              "model_kwargs": model_kwargs, "torch_threads": threads, "machine": machine_info()}
    write_json(out / "config.json", config)
    curve = LearningCurveCallback(out, args.eval_freq, eval_soils, args.eval_seeds, env_kwargs=model_env, verbose=1)
    callbacks = [curve]
    if args.checkpoint_freq > 0:
        callbacks.append(CheckpointCallback(max(args.checkpoint_freq // args.n_envs, 1), str(out / "checkpoints"),
                                            name_prefix=algo))
    load0 = machine_info()["loadavg_1_5_15min"]
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, callback=CallbackList(callbacks),
                progress_bar=args.progress_bar, tb_log_name=f"{algo}_{args.setup}")
    wall = time.perf_counter() - t0
    model.save(out / "model.zip")
    env.close()
    steps = int(model.num_timesteps)
    summary = {
        "algo": algo, "setup": args.setup, "timesteps": steps, "wall_s": wall,
        "learning_curve_eval_s": curve.eval_time,
        "env_steps_per_s": steps / wall, "env_steps_per_s_excluding_curve_eval": steps / max(wall - curve.eval_time,
                                                                                             1e-9),
        "loadavg_before": load0, "loadavg_after": machine_info()["loadavg_1_5_15min"],
        "final_eval": curve.records[-1] if curve.records else None, "model": str(out / "model.zip"),
    }
    write_json(out / "train_summary.json", summary)
    print(f"{algo.upper()} {args.setup}: {steps} env-steps in {wall:.1f} s "
          f"({summary['env_steps_per_s_excluding_curve_eval']:.0f} env-steps/s without curve evaluations); "
          f"model -> {out / 'model.zip'}", flush=True)
    return summary
