"""Speed of the bucket-loading envs: single env steps/s and batched env-steps/s.

Measures, in one run and with the same random digging actions:

* the single env raw (``env.unwrapped.step``) and through ``gym.make``'s
  wrappers (TimeLimit, OrderEnforcing, PassiveEnvChecker);
* the NumPy-batched vector env (``gym.make_vec``, vector entry point) for
  64, 256 and 1024 envs;
* Gymnasium's ``SyncVectorEnv`` of single envs (baseline) for 64 envs.

Episodes end and auto-reset during the runs (reset cost is included).
Writes ``env_speed.json`` and ``env_speed.png`` into ``--out``.

Usage: ``python benchmarks/env_speed.py [--out results/env_speed] [--seed 0] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from wheelloader.provenance import machine_info

TARGET_SINGLE = 20_000.0
TARGET_BATCHED = 500_000.0


def digging_actions(steps: int, num_envs: int, seed: int) -> np.ndarray:
    """Random actions that dig for half a second, then lift, so episodes end and reset."""
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (steps, num_envs, 3)).astype(np.float32)
    acts[:, :, 0] = np.abs(acts[:, :, 0])
    lift = (np.arange(steps) % 60) >= 30
    acts[lift, :, 1] = np.abs(acts[lift, :, 1])
    return acts


def time_single(env, actions: np.ndarray, seed: int, max_episode_steps: int = 600) -> tuple[float, int]:
    """Steps per second of a single env over ``actions`` (resets on episode end, and after
    ``max_episode_steps`` for an unwrapped env, so raw and wrapped runs see the same episodes)."""
    env.reset(seed=seed)
    resets = 0
    steps = 0
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        steps += 1
        if terminated or truncated or steps >= max_episode_steps:
            env.reset()
            resets += 1
            steps = 0
    elapsed = time.perf_counter() - start
    return len(actions) / elapsed, resets


def time_vector(envs, actions: np.ndarray, seed: int, warmup: int = 5) -> float:
    """Env-steps per second of a vector env over ``actions``."""
    envs.reset(seed=seed)
    for a in actions[:warmup]:
        envs.step(a)
    start = time.perf_counter()
    for a in actions[warmup:]:
        envs.step(a)
    elapsed = time.perf_counter() - start
    return (len(actions) - warmup) * actions.shape[1] / elapsed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.replace("``", ""),  # plain text, not reST
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/env_speed", help="output directory")
    parser.add_argument("--seed", type=int, default=0, help="seed of the env and the actions")
    parser.add_argument("--repeats", type=int, default=3, help="repetitions per measurement (best is reported)")
    parser.add_argument("--single-steps", type=int, default=20_000, help="steps per single-env run")
    parser.add_argument("--batched-steps", type=int, default=100, help="batched steps per vector-env run")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 1024], help="numbers of batched envs")
    args = parser.parse_args(argv)

    import gymnasium as gym

    import wheelloader.envs  # noqa: F401  (registers the ids)

    env_id = "wheelloader/BucketLoading-v0"
    results: dict[str, object] = {"benchmark": "env_speed", "env_id": env_id, "seed": args.seed,
                                  "repeats": args.repeats, "machine": machine_info()}

    single_actions = digging_actions(args.single_steps, 1, args.seed)[:, 0]
    single: dict[str, dict[str, float]] = {}
    for label in ("raw", "gym_make"):
        rates = []
        for _ in range(args.repeats):
            env = gym.make(env_id)
            target = env.unwrapped if label == "raw" else env
            rate, resets = time_single(target, single_actions, args.seed)
            rates.append(rate)
        single[label] = {"steps_per_s_best": max(rates), "steps_per_s_median": statistics.median(rates),
                         "resets_per_run": resets, "steps_per_run": args.single_steps}
        print(f"single env ({label}): {max(rates):,.0f} steps/s (median {statistics.median(rates):,.0f})")
    results["single"] = single

    batched: dict[str, dict[str, float]] = {}
    for n in args.sizes:
        actions = digging_actions(args.batched_steps, n, args.seed + n)
        rates = []
        for _ in range(args.repeats):
            envs = gym.make_vec(env_id, num_envs=n)
            rates.append(time_vector(envs, actions, args.seed))
            envs.close()
        batched[str(n)] = {"env_steps_per_s_best": max(rates), "env_steps_per_s_median": statistics.median(rates),
                           "batched_steps_per_run": args.batched_steps}
        print(f"batched vector env, {n} envs: {max(rates):,.0f} env-steps/s (median {statistics.median(rates):,.0f})")
    results["batched"] = batched

    n_sync = min(args.sizes)
    actions = digging_actions(max(args.batched_steps // 4, 10), n_sync, args.seed + n_sync)
    envs = gym.make_vec(env_id, num_envs=n_sync, vectorization_mode="sync")
    sync_rate = time_vector(envs, actions, args.seed)
    envs.close()
    results["sync_vector_baseline"] = {str(n_sync): {"env_steps_per_s": sync_rate}}
    print(f"SyncVectorEnv baseline, {n_sync} envs: {sync_rate:,.0f} env-steps/s")

    best_batched = max(v["env_steps_per_s_best"] for v in batched.values())
    results["targets"] = {
        "single_steps_per_s": TARGET_SINGLE, "batched_env_steps_per_s": TARGET_BATCHED,
        "single_met": single["raw"]["steps_per_s_best"] >= TARGET_SINGLE,
        "batched_met": best_batched >= TARGET_BATCHED,
    }

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "env_speed.json").write_text(json.dumps(results, indent=2))
    _plot(results, out / "env_speed.png")
    print(f"wrote {out / 'env_speed.json'} and {out / 'env_speed.png'}")
    return 0


def _plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    labels, values = [], []
    for key, val in results["single"].items():
        labels.append(f"single\n{key}")
        values.append(val["steps_per_s_best"])
    for key, val in results["sync_vector_baseline"].items():
        labels.append(f"sync\n{key}")
        values.append(val["env_steps_per_s"])
    for key, val in results["batched"].items():
        labels.append(f"batched\n{key}")
        values.append(val["env_steps_per_s_best"])
    ax.bar(labels, values, color=["tab:blue"] * 2 + ["tab:gray"] + ["tab:orange"] * len(results["batched"]))
    ax.axhline(TARGET_SINGLE, color="tab:blue", ls="--", lw=1, label="single target 20k")
    ax.axhline(TARGET_BATCHED, color="tab:orange", ls="--", lw=1, label="batched target 500k")
    ax.set_yscale("log")
    ax.set_ylabel("env steps / s")
    ax.set_title("BucketLoading-v0 speed", fontsize=10)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
