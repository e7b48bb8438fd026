"""Train SAC (stable-baselines3) on the batched bucket-loading env.

Same set-ups, outputs and common options as ``train/ppo.py`` (see there);
the model loads with ``SAC.load``. SAC does one gradient step per
``--train-freq`` vector steps and is much slower per env-step than PPO on a
CPU: budget accordingly.

Usage::

    python train/sac.py --setup randomized --total-timesteps 100000 --out results/sac_randomized
"""

from __future__ import annotations

import argparse

from training import add_training_args, train


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_training_args(parser, default_steps=100_000, default_envs=8)
    parser.add_argument("--buffer-size", type=int, default=300_000)
    parser.add_argument("--learning-starts", type=int, default=5_000, help="env-steps of random actions first")
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--train-freq", type=int, default=1, help="vector steps between updates")
    parser.add_argument("--gradient-steps", type=int, default=2, help="gradient steps per update")
    parser.add_argument("--learning-rate", type=float, default=3e-4)
    parser.add_argument("--gamma", type=float, default=0.99)
    parser.add_argument("--use-sde", action=argparse.BooleanOptionalAction, default=False,
                        help="generalised state-dependent exploration (gSDE)")
    parser.add_argument("--net-arch", type=int, nargs="+", default=[128, 128], help="hidden layer sizes")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and train."""
    args = build_parser().parse_args(argv)
    model_kwargs = {"buffer_size": args.buffer_size, "learning_starts": args.learning_starts,
                    "batch_size": args.batch_size, "train_freq": args.train_freq,
                    "gradient_steps": args.gradient_steps, "learning_rate": args.learning_rate, "gamma": args.gamma,
                    "use_sde": args.use_sde, "policy_kwargs": {"net_arch": list(args.net_arch)}}
    train("sac", args, model_kwargs)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
