"""Speed of the bucket-loading envs against an older version of the package and against CartPole-v1, in one run.

Each repeat starts one worker process per package version (this checkout, and ``--old-ref`` exported from git
into a temporary folder and put first on ``sys.path``), in alternating order, so old and new see the same
machine load. A worker measures, with the same random digging actions:

* CartPole-v1 and the single env, raw (``env.unwrapped.step``) and through ``gym.make``'s wrappers,
  interleaved in the same process (their ratio is the figure the issue asks for);
* the NumPy-batched vector env (``gym.make_vec``, vector entry point) at ``--sizes`` envs;
* with stable-baselines3 installed (``--sb3``): PPO's throughput (``PPO.learn``, env-steps per second, and the
  rollout collection alone) on ``make_sb3_vec_env`` and on SB3's ``DummyVecEnv`` of single envs at
  ``--sb3-sizes`` envs.

Times are CPU seconds of the worker (``time.process_time``), which other jobs on the machine disturb less than
wall time; the load average before and after each worker is recorded beside them. Episodes end and reset
during the runs (reset cost is included). Writes ``env_speed.json`` and ``env_speed.png`` into ``--out``.

Usage::

    python benchmarks/env_speed.py --old-ref 1fc58d3 --out docs/results/env_speed [--repeats 3] [--sb3]
    python benchmarks/env_speed.py --quick --out /tmp/env_speed          # a smoke run (this version only)
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ENV_ID = "wheelloader/BucketLoading-v0"
#: Targets of issue #31 item 5.
TARGET_RATIO = 0.5
TARGET_BATCHED = 1_000_000.0
ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ worker (runs in its own process)
def digging_actions(steps: int, num_envs: int, seed: int) -> np.ndarray:
    """Random actions that dig for half a second, then lift, so episodes end and reset."""
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (steps, num_envs, 3)).astype(np.float32)
    acts[:, :, 0] = np.abs(acts[:, :, 0])
    lift = (np.arange(steps) % 60) >= 30
    acts[lift, :, 1] = np.abs(acts[lift, :, 1])
    return acts


def _cpu_rate(run, steps: int, tries: int) -> float:
    """Steps per CPU second of ``run()`` (which makes ``steps`` steps), best of ``tries``."""
    best = float("inf")
    for _ in range(tries):
        start = time.process_time()
        run()
        best = min(best, time.process_time() - start)
    return steps / best


def _single_runner(env, actions, max_steps: int):
    state = {"k": 0}

    def run() -> None:
        k = state["k"]
        for a in actions:
            _, _, terminated, truncated, _ = env.step(a)
            k += 1
            if terminated or truncated or k >= max_steps:
                env.reset()
                k = 0
        state["k"] = k
    return run


def measure_single(steps: int, seed: int, tries: int) -> dict:
    """CartPole-v1 and the bucket-loading env, raw and through gym.make, interleaved in one process."""
    import gymnasium as gym

    import wheelloader.envs  # noqa: F401  (registers the ids)

    actions = digging_actions(steps, 1, seed)[:, 0]
    cart_actions = np.random.default_rng(seed).integers(0, 2, steps).tolist()
    out: dict[str, dict[str, float]] = {}
    for label in ("raw", "gym_make"):
        ours = gym.make(ENV_ID)
        cart = gym.make("CartPole-v1")
        ours, cart = (ours.unwrapped, cart.unwrapped) if label == "raw" else (ours, cart)
        ours.reset(seed=seed)
        cart.reset(seed=seed)
        run_ours = _single_runner(ours, actions, 600)
        run_cart = _single_runner(cart, cart_actions, 500)
        rates_ours, rates_cart = [], []
        for _ in range(tries):  # interleaved: both see the same moments of the machine
            rates_cart.append(_cpu_rate(run_cart, steps, 1))
            rates_ours.append(_cpu_rate(run_ours, steps, 1))
        out[label] = {"steps_per_s": max(rates_ours), "cartpole_steps_per_s": max(rates_cart),
                      "ratio_to_cartpole": max(rates_ours) / max(rates_cart),
                      "ratio_to_cartpole_median": statistics.median(a / b for a, b in zip(rates_ours, rates_cart,
                                                                                          strict=True))}
    return out


def measure_batched(sizes: list[int], steps: int, seed: int, tries: int) -> dict:
    """Env-steps per CPU second of the batched vector env (after a warm-up of 5 steps)."""
    import gymnasium as gym

    import wheelloader.envs  # noqa: F401

    out = {}
    for n in sizes:
        actions = digging_actions(steps + 5, n, seed + n)
        envs = gym.make_vec(ENV_ID, num_envs=n)
        envs.reset(seed=seed)
        for a in actions[:5]:
            envs.step(a)

        def run(envs=envs, actions=actions) -> None:
            for a in actions[5:]:
                envs.step(a)
        out[str(n)] = {"env_steps_per_s": _cpu_rate(run, steps * n, tries), "batched_steps": steps}
        envs.close()
    return out


def measure_sb3(sizes: list[int], rollouts: int, seed: int, tries: int) -> dict:
    """PPO on make_sb3_vec_env and on DummyVecEnv of single envs: env-steps per CPU second of PPO.learn and of
    the rollout collection alone (the env's share)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    import wheelloader.envs  # noqa: F401
    from wheelloader.envs.sb3 import make_sb3_vec_env

    torch.set_num_threads(1)
    n_steps = 128
    out: dict[str, dict] = {}
    for n in sizes:
        def packaged(n=n):
            return make_sb3_vec_env(ENV_ID, n, seed=seed)

        def batched(n=n):
            return make_sb3_vec_env(ENV_ID, n, seed=seed, backend="batched")

        def dummy(n=n):
            venv = VecMonitor(DummyVecEnv([lambda: gym.make(ENV_ID) for _ in range(n)]))
            venv.seed(seed)
            return venv
        row = {}
        variants = [("make_sb3_vec_env", packaged), ("DummyVecEnv", dummy)]
        if "backend" in inspect.signature(make_sb3_vec_env).parameters:  # the batched adapter alone
            variants.append(("batched adapter", batched))
        for label, make in variants:
            learn, collect = [], []
            for _ in range(tries):
                venv = make()
                model = PPO("MlpPolicy", venv, n_steps=n_steps, batch_size=256, n_epochs=2, seed=seed, device="cpu")
                total = rollouts * n_steps * n
                start = time.process_time()
                model.learn(total_timesteps=total)
                learn.append(total / (time.process_time() - start))
                start = time.process_time()
                for _ in range(rollouts):
                    venv.reset()
                    for _ in range(n_steps):
                        venv.step(np.stack([venv.action_space.sample() for _ in range(n)]))
                collect.append(rollouts * n_steps * n / (time.process_time() - start))
                venv.close()
            row[label] = {"learn_env_steps_per_s": max(learn), "env_steps_per_s": max(collect)}
        ours, theirs = row["make_sb3_vec_env"], row["DummyVecEnv"]
        row["ratio_learn"] = ours["learn_env_steps_per_s"] / theirs["learn_env_steps_per_s"]
        row["ratio_env"] = ours["env_steps_per_s"] / theirs["env_steps_per_s"]
        if "batched adapter" in row:
            row["ratio_learn_batched_adapter"] = (row["batched adapter"]["learn_env_steps_per_s"]
                                                  / theirs["learn_env_steps_per_s"])
        out[str(n)] = row
    return out


def worker(args: argparse.Namespace) -> int:
    import wheelloader

    result = {"package": str(Path(wheelloader.__file__).resolve().parent), "load_before": os.getloadavg()}
    result["single"] = measure_single(args.single_steps, args.seed, args.tries)
    result["batched"] = measure_batched(args.sizes, args.batched_steps, args.seed, args.tries)
    if args.sb3:
        result["sb3"] = measure_sb3(args.sb3_sizes, args.sb3_rollouts, args.seed, min(args.tries, 2))
    result["load_after"] = os.getloadavg()
    print(json.dumps(result))
    return 0


# ------------------------------------------------------------------ parent
def export_version(ref: str, into: Path) -> Path:
    """``ref``'s package, laid out as an importable ``wheelloader`` package; the directory to import from."""
    from wheelloader.provenance import package_at_revision  # here: a worker may run an older package

    return package_at_revision(ROOT, ref, into)[1]


def run_worker(args: argparse.Namespace, site: Path | None) -> dict:
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")])
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", "--seed", str(args.seed),
               "--tries", str(args.tries), "--single-steps", str(args.single_steps),
               "--batched-steps", str(args.batched_steps), "--sizes", *map(str, args.sizes)]
    if args.sb3:
        command += ["--sb3", "--sb3-rollouts", str(args.sb3_rollouts), "--sb3-sizes", *map(str, args.sb3_sizes)]
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=False, cwd=tempfile.gettempdir())
    if done.returncode != 0:
        raise SystemExit(f"env_speed: worker failed ({'old' if site else 'new'}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def summarize(runs: list[dict]) -> dict:
    """Best over repeats of every figure (the least disturbed run), and the ratios of the best."""
    single = {label: {key: max(r["single"][label][key] for r in runs)
                      for key in ("steps_per_s", "cartpole_steps_per_s", "ratio_to_cartpole")}
              for label in runs[0]["single"]}
    batched = {n: max(r["batched"][n]["env_steps_per_s"] for r in runs) for n in runs[0]["batched"]}
    out = {"single": single, "batched_env_steps_per_s": batched}
    if "sb3" in runs[0]:
        out["sb3"] = {n: {key: max(r["sb3"][n][key] for r in runs) if key.startswith("ratio") else
                          {k: max(r["sb3"][n][key][k] for r in runs) for k in runs[0]["sb3"][n][key]}
                          for key in runs[0]["sb3"][n]} for n in runs[0]["sb3"]}
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.replace("``", ""),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="results/env_speed", help="output directory (default results/env_speed)")
    parser.add_argument("--old-ref", default=None,
                        help="git revision of the older version to measure beside this checkout (e.g. 1fc58d3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the envs and the actions (default 0)")
    parser.add_argument("--repeats", type=int, default=3, help="worker processes per version (default 3)")
    parser.add_argument("--tries", type=int, default=5, help="timed passes per figure inside a worker (default 5)")
    parser.add_argument("--single-steps", type=int, default=4000, help="steps per single-env pass (default 4000)")
    parser.add_argument("--batched-steps", type=int, default=100, help="batched steps per pass (default 100)")
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 256, 1024],
                        help="numbers of batched envs (default 64 256 1024)")
    parser.add_argument("--sb3", action="store_true", help="also PPO on make_sb3_vec_env against DummyVecEnv "
                        "(needs stable-baselines3 and torch)")
    parser.add_argument("--sb3-sizes", type=int, nargs="+", default=[8, 16, 32, 64],
                        help="numbers of envs of the SB3 comparison (default 8 16 32 64)")
    parser.add_argument("--sb3-rollouts", type=int, default=2,
                        help="PPO rollouts of 128 steps per SB3 run (default 2; best of 2 runs)")
    parser.add_argument("--quick", action="store_true", help="a smoke run: small counts, one repeat")
    parser.add_argument("--report", action="store_true",
                        help="only rewrite env_speed.md and env_speed.png from the env_speed.json in --out")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.quick:
        args.repeats, args.tries, args.single_steps, args.batched_steps = 1, 1, 300, 10
        args.sizes, args.sb3_sizes, args.sb3_rollouts = [16], [4], 1
    if args.worker:
        return worker(args)
    out = Path(args.out)
    if args.report:
        results = json.loads((out / "env_speed.json").read_text())
        (out / "env_speed.md").write_text(table(results))
        _plot(results, out / "env_speed.png")
        print(f"wrote {out / 'env_speed.md'} and {out / 'env_speed.png'}")
        return 0

    from wheelloader.provenance import machine_info

    results: dict = {"benchmark": "env_speed", "env_id": ENV_ID, "seed": args.seed, "repeats": args.repeats,
                     "tries": args.tries, "timing": "CPU seconds of the worker process (time.process_time)",
                     "old_ref": args.old_ref, "machine": machine_info(),
                     "targets": {"single_ratio_to_cartpole": TARGET_RATIO, "batched_env_steps_per_s": TARGET_BATCHED,
                                 "sb3_ratio_to_dummy": 1.0}}
    runs: dict[str, list[dict]] = {"new": [], "old": []} if args.old_ref else {"new": []}
    with tempfile.TemporaryDirectory(prefix="env_speed_") as tmp:
        site = export_version(args.old_ref, Path(tmp)) if args.old_ref else None
        for rep in range(args.repeats):
            order = ["new", "old"] if rep % 2 == 0 else ["old", "new"]
            for version in order:
                if version not in runs:
                    continue
                run = run_worker(args, site if version == "old" else None)
                if version == "old" and not run["package"].startswith(tmp):
                    raise SystemExit(f"env_speed: the old worker imported {run['package']}, not the export")
                runs[version].append(run)
                single = run["single"]["raw"]
                print(f"repeat {rep + 1} {version}: single {single['steps_per_s']:,.0f} steps/s = "
                      f"{single['ratio_to_cartpole']:.2f}x CartPole; batched "
                      + ", ".join(f"{n}: {v['env_steps_per_s']:,.0f}" for n, v in run["batched"].items())
                      + f" env-steps/s (load {run['load_before'][0]:.1f})", flush=True)
    results["runs"] = runs
    results["summary"] = {version: summarize(r) for version, r in runs.items()}
    new = results["summary"]["new"]
    biggest = str(max(args.sizes))
    results["met"] = {
        "single_ratio": new["single"]["raw"]["ratio_to_cartpole"] >= TARGET_RATIO,
        "batched": new["batched_env_steps_per_s"][biggest] >= TARGET_BATCHED,
    }
    if "sb3" in new:
        results["met"]["sb3"] = all(row["ratio_learn"] >= 0.97 for n, row in new["sb3"].items() if n in ("8", "16"))
    loads = [run[key][0] for rs in runs.values() for run in rs for key in ("load_before", "load_after")]
    results["load_average_1min"] = {"min": min(loads), "max": max(loads)}
    out.mkdir(parents=True, exist_ok=True)
    (out / "env_speed.json").write_text(json.dumps(results, indent=2) + "\n")
    (out / "env_speed.md").write_text(table(results))
    _plot(results, out / "env_speed.png")
    print(json.dumps({"summary": results["summary"], "met": results["met"],
                      "load_average_1min": results["load_average_1min"]}, indent=1))
    print(f"wrote {out / 'env_speed.json'} and {out / 'env_speed.png'}")
    return 0


def table(results: dict) -> str:
    """The Markdown table of a run (best of the repeats; CPU seconds; the load beside it)."""
    summary = results["summary"]
    versions = list(summary)
    head = ["figure"] + [f"{v} ({results['old_ref']})" if v == "old" else "this version" for v in versions]
    rows = []
    for label in summary["new"]["single"]:
        rows.append([f"single env, {label.replace('_', '.')}: steps/s"]
                    + [f"{summary[v]['single'][label]['steps_per_s']:,.0f}" for v in versions])
        rows.append([f"single env, {label.replace('_', '.')}: relative to CartPole-v1 (target >= 0.5)"]
                    + [f"{summary[v]['single'][label]['ratio_to_cartpole']:.2f}" for v in versions])
    for n in summary["new"]["batched_env_steps_per_s"]:
        rows.append([f"batched env, {n} envs: env-steps/s" + (" (target >= 1M)" if n == "1024" else "")]
                    + [f"{summary[v]['batched_env_steps_per_s'][n]:,.0f}" for v in versions])
    for n, row in summary["new"].get("sb3", {}).items():
        old = summary.get("old", {}).get("sb3", {}).get(n)
        rows.append([f"PPO on make_sb3_vec_env / DummyVecEnv, {n} envs (target >= 1 at 8, 16)",
                     f"{row['ratio_learn']:.2f}"] + ([f"{old['ratio_learn']:.2f}"] if "old" in summary else []))
        if "ratio_learn_batched_adapter" in row:
            rows.append([f"PPO on the batched adapter / DummyVecEnv, {n} envs",
                         f"{row['ratio_learn_batched_adapter']:.2f}"] + (["-"] if "old" in summary else []))
    load = results["load_average_1min"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows]
    lines.append(f"\nBest of {results['repeats']} worker processes per version x {results['tries']} passes, CPU "
                 f"seconds; load average {load['min']:.1f}-{load['max']:.1f} (2 cores).")
    return "\n".join(lines) + "\n"


def _plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    summary = results["summary"]
    versions = list(summary)
    colours = {"new": "tab:orange", "old": "tab:gray"}
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.6, 3.6), gridspec_kw={"width_ratios": [1, 1.6]})
    labels = list(summary["new"]["single"])
    width = 0.8 / len(versions)
    for k, version in enumerate(versions):
        ratios = [summary[version]["single"][label]["ratio_to_cartpole"] for label in labels]
        ax1.bar(np.arange(len(labels)) + k * width, ratios, width, color=colours[version],
                label=f"{version}" + (f" ({results['old_ref']})" if version == "old" else ""))
    ax1.axhline(TARGET_RATIO, color="k", ls="--", lw=1, label="target 0.5")
    ax1.set_xticks(np.arange(len(labels)) + width * (len(versions) - 1) / 2, [f"single {label}" for label in labels])
    ax1.set_ylabel("steps/s relative to CartPole-v1")
    ax1.legend(fontsize=8)
    sizes = list(summary["new"]["batched_env_steps_per_s"])
    for k, version in enumerate(versions):
        values = [summary[version]["batched_env_steps_per_s"][n] for n in sizes]
        ax2.bar(np.arange(len(sizes)) + k * width, values, width, color=colours[version], label=version)
    ax2.axhline(TARGET_BATCHED, color="k", ls="--", lw=1, label="target 1M at 1024")
    ax2.set_xticks(np.arange(len(sizes)) + width * (len(versions) - 1) / 2, [f"batched {n}" for n in sizes])
    ax2.set_ylabel("env-steps / CPU s")
    ax2.legend(fontsize=8)
    load = results["load_average_1min"]
    fig.suptitle(f"BucketLoading-v0 speed (load average {load['min']:.1f}-{load['max']:.1f})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
