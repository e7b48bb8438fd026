"""Training speed: PPO env-steps/s on the batched vector env and on SB3's DummyVecEnv of single envs.

Runs short PPO trainings (no learning-curve evaluation, no checkpoints) with
the same settings as ``train/ppo.py`` and reports env-steps/s, the machine's
load average before and after each run, and torch's thread count.

Writes ``speed.json`` into ``--out`` (default ``results/train_speed``).

Usage::

    python train/speed.py --total-timesteps 131072 --out results/train_speed
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from common import machine_info, set_torch_threads, write_json
from setups import VEC_BACKENDS, make_train_env

TARGET = 1000.0


def measure(vec: str, n_envs: int, steps: int, seed: int, use_sde: bool, n_epochs: int = 10) -> dict:
    """One PPO run; env-steps/s of ``model.learn`` (rollouts plus updates).

    Parameters
    ----------
    vec : str
        ``"batched"`` or ``"dummy"`` (see :func:`setups.make_train_env`).
    n_envs : int
        Sub-envs.
    steps : int
        Env-steps to train.
    seed : int
        Seed of the envs and the policy.
    use_sde : bool
        gSDE exploration.
    n_epochs : int
        PPO epochs per update (``train/ppo.py``'s default is 10).

    Returns
    -------
    dict
        Settings, wall time, env-steps/s and the load average before and after.
    """
    from stable_baselines3 import PPO

    env = make_train_env({"soil": "random"}, n_envs, seed, vec)
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=512, n_epochs=n_epochs, gamma=0.995, use_sde=use_sde,
                policy_kwargs={"net_arch": [64, 64]}, seed=seed, device="cpu")
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    wall = time.perf_counter() - t0
    env.close()
    return {"vec": vec, "n_envs": n_envs, "use_sde": use_sde, "n_epochs": n_epochs,
            "timesteps": int(model.num_timesteps), "wall_s": wall,
            "env_steps_per_s": model.num_timesteps / wall, "loadavg_before": list(load0),
            "loadavg_after": list(os.getloadavg())}


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, measure, write JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--total-timesteps", type=int, default=131_072)
    parser.add_argument("--n-envs", type=int, default=16)
    parser.add_argument("--vec", nargs="+", default=["batched", "dummy"], choices=VEC_BACKENDS)
    parser.add_argument("--sde", nargs="+", default=["on"], choices=("on", "off"), help="gSDE settings to measure")
    parser.add_argument("--n-epochs", type=int, default=10, help="PPO epochs per update (train/ppo.py's default)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/train_speed"))
    args = parser.parse_args(argv)
    threads = set_torch_threads(args.torch_threads)
    runs = []
    for sde in args.sde:
        for vec in args.vec:
            r = measure(vec, args.n_envs, args.total_timesteps, args.seed, sde == "on", args.n_epochs)
            runs.append(r)
            print(f"PPO {vec:>7} n_envs={args.n_envs} gSDE={sde}: {r['env_steps_per_s']:.0f} env-steps/s "
                  f"({r['timesteps']} steps in {r['wall_s']:.1f} s; load {r['loadavg_before'][0]:.2f} -> "
                  f"{r['loadavg_after'][0]:.2f})", flush=True)
    write_json(args.out / "speed.json", {"machine": machine_info(), "torch_threads": threads, "target": TARGET,
                                         "runs": runs})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
