"""Train PPO (stable-baselines3) on the batched bucket-loading env.

Set-ups (``--setup``):

* ``randomized``: the plant with the hidden soil drawn uniformly from the
  soil presets at every reset (domain randomisation);
* ``twin``: one cycle on the plant (``--plant-soil``) with the reference
  Bezier path is calibrated (``wheelloader.estimator.calibrate``) and PPO
  trains on the env running the calibrated parameters (the digital twin);
  evaluate it on the plant with ``train/evaluate.py``.

Writes into ``--out`` (default ``results/ppo_<setup>``): ``model.zip``
(``PPO.load``), ``config.json``, ``learning_curve.json``,
``train_summary.json``, ``checkpoints/`` and, with ``--tensorboard``, ``tb/``.

Usage::

    python train/ppo.py --setup randomized --total-timesteps 1000000 --out results/ppo_randomized
    python train/ppo.py --setup twin --plant-soil lean_clay --total-timesteps 500000 --out results/ppo_twin
"""

from __future__ import annotations

import argparse

from training import add_training_args, train


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_training_args(parser, default_steps=1_000_000, default_envs=16)
    parser.add_argument("--n-steps", type=int, default=256, help="rollout length per sub-env")
    parser.add_argument("--batch-size", type=int, default=512, help="minibatch size")
    parser.add_argument("--n-epochs", type=int, default=10,
                        help="epochs per update (train/README.md compares 10 with 5)")
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--gamma", type=float, default=0.995)
    parser.add_argument("--ent-coef", type=float, default=0.0)
    parser.add_argument("--use-sde", action=argparse.BooleanOptionalAction, default=True,
                        help="generalised state-dependent exploration (gSDE, default on: with plain Gaussian noise "
                             "PPO learns to stay out of the pile)")
    parser.add_argument("--sde-sample-freq", type=int, default=-1, help="gSDE noise resampling period [steps]")
    parser.add_argument("--log-std-init", type=float, default=0.0, help="initial log std of the action noise")
    parser.add_argument("--net-arch", type=int, nargs="+", default=[64, 64], help="hidden layer sizes")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and train."""
    args = build_parser().parse_args(argv)
    n_steps = args.n_steps
    batch = min(args.batch_size, n_steps * args.n_envs)
    model_kwargs = {"n_steps": n_steps, "batch_size": batch, "n_epochs": args.n_epochs,
                    "learning_rate": args.learning_rate, "gamma": args.gamma, "ent_coef": args.ent_coef,
                    "use_sde": args.use_sde, "sde_sample_freq": args.sde_sample_freq,
                    "policy_kwargs": {"net_arch": list(args.net_arch), "log_std_init": args.log_std_init}}
    train("ppo", args, model_kwargs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
