"""Is the single env's ratio to CartPole-v1 lower on a busy machine because other jobs evict its caches?

The single env and CartPole-v1 step alternately in one process (``env.unwrapped.step``, the benchmark's
digging actions); before every block of ``--block`` steps a 32 MB array is summed, which evicts the caches as a
context switch to a large job would. Only the steps' CPU time counts. If cache eviction explained the load
dependence, the ratio would fall as the blocks get shorter.

Usage::

    python benchmarks/env_speed_load.py --steps 3000 --tries 5 --blocks 3000 200 50 10
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

ENV_ID = "wheelloader/BucketLoading-v0"


def digging_actions(steps: int, seed: int) -> np.ndarray:
    """``benchmarks/env_speed.py``'s actions for one env (benchmarks import no other benchmark): random actions
    that dig for half a second, then lift, so episodes end and reset."""
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (steps, 1, 3)).astype(np.float32)
    acts[:, :, 0] = np.abs(acts[:, :, 0])
    lift = (np.arange(steps) % 60) >= 30
    acts[lift, :, 1] = np.abs(acts[lift, :, 1])
    return acts[:, 0]


def _rate(env, actions, max_steps: int, block: int, junk: np.ndarray) -> float:
    """Steps per CPU second of the steps alone, the caches evicted before each block (none for one block)."""
    k, total = 0, 0.0
    for s in range(0, len(actions), block):
        if block < len(actions):
            junk.sum()
        start = time.process_time()
        for a in actions[s:s + block]:
            _, _, terminated, truncated, _ = env.step(a)
            k += 1
            if terminated or truncated or k >= max_steps:
                env.reset()
                k = 0
        total += time.process_time() - start
    return len(actions) / total


def measure(steps: int, tries: int, blocks: list[int], seed: int = 0) -> list[dict]:
    """One row per block length: best rates of both envs and the ratio (best and median over ``tries``)."""
    import gymnasium as gym

    import wheelloader.envs  # noqa: F401  (registers the ids)

    ours = gym.make(ENV_ID).unwrapped
    cart = gym.make("CartPole-v1").unwrapped
    ours.reset(seed=seed)
    cart.reset(seed=seed)
    actions = digging_actions(steps, seed)
    cart_actions = np.random.default_rng(seed).integers(0, 2, steps).tolist()
    junk = np.ones(4 * 1024 * 1024)  # 32 MB
    rows = []
    for block in blocks:
        pairs = [(_rate(ours, actions, 600, block, junk), _rate(cart, cart_actions, 500, block, junk))
                 for _ in range(tries)]
        best_o, best_c = max(p[0] for p in pairs), max(p[1] for p in pairs)
        rows.append({"block": block, "steps_per_s": best_o, "cartpole_steps_per_s": best_c,
                     "ratio_best": best_o / best_c, "ratio_median": statistics.median(o / c for o, c in pairs)})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--tries", type=int, default=5)
    parser.add_argument("--blocks", type=int, nargs="+", default=[3000, 200, 50, 10])
    args = parser.parse_args(argv)
    for row in measure(args.steps, args.tries, args.blocks):
        print(f"caches evicted every {row['block']:5d} steps: ours {row['steps_per_s']:8,.0f}/s, CartPole "
              f"{row['cartpole_steps_per_s']:8,.0f}/s, ratio {row['ratio_best']:.3f}"
              f" (median {row['ratio_median']:.3f})")
    print("load average " + " ".join(f"{v:.1f}" for v in os.getloadavg()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
