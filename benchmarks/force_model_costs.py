"""What each force model costs where it runs: the env's step and the planner's cold plan, per ``FORCE_MODELS`` name.

#32 asks that the model selected by ``force_model=`` cost at most 2x the FEE's env step and 1.5x the FEE's
median cold plan. For every name of :data:`wheelloader.estimator.FORCE_MODELS`, in one process (the models
alternate within every round, so a change of the machine's load hits them alike):

* env step: CPU time per step (``time.process_time``) of ``BucketLoadingEnv(force_model=name)`` over
  ``--steps`` seeded random digging actions (forward, lifting out every other second; resets at episode ends),
  best of ``--rounds`` rounds;
* cold plan: ``TrajectoryOptimizer(options=PlannerOptions(force_model=name)).solve`` after
  ``reset_warm_start()`` with the default initial guess, on the default pile from the env's nominal start, per
  soil of ``--soils`` and ``--repeats`` times (the planner benchmark's "full-cycle plan, cold"): wall and CPU
  time, IPOPT status and iterations; the NLP's build (or load from the disk cache) is timed apart. Each plan
  is checked with the NumPy model of the same name (:func:`~wheelloader.planner.verify_plan`), which gives its
  fill (the payload's kept soil under ``"fee-payload"``) and its carved volume.

Writes ``results.json`` and ``table.md`` (the table the docs include) into ``--out``; the load average is
recorded before and after.

Usage::

    python benchmarks/force_model_costs.py --out docs/results/force_model_costs
    python benchmarks/force_model_costs.py --quick --out /tmp/costs     # 1 soil, 1 repeat, 5k steps
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from wheelloader.estimator.jsonable import to_jsonable  # noqa: E402
from wheelloader.provenance import machine_info  # noqa: E402

#: The issue's limits: the env step and the median cold plan, as multiples of the FEE's.
STEP_LIMIT, PLAN_LIMIT = 2.0, 1.5


def env_step_seconds(name: str, steps: int, seed: int = 0) -> float:
    """CPU seconds per step of the single env with force model ``name`` (module docstring)."""
    from wheelloader.envs import BucketLoadingEnv

    env = BucketLoadingEnv(force_model=name)
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (steps, 3)).astype(np.float32)
    acts[:, 0] = np.abs(acts[:, 0])
    lift = (np.arange(steps) % 120) >= 60
    acts[lift, 1] = np.abs(acts[lift, 1])
    env.reset(seed=seed)
    tic = time.process_time()
    for a in acts:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return (time.process_time() - tic) / steps


def cold_plans(name: str, soils: list[str], repeats: int) -> dict[str, Any]:
    """Build the planner of ``name`` and time its cold plans (module docstring)."""
    from wheelloader.estimator import Pile
    from wheelloader.planner import PlannerOptions, TrajectoryOptimizer, cycle_duration, default_start, verify_plan

    pile = Pile.trapezoid()
    start = default_start(pile)
    duration = cycle_duration(pile, start)
    tic, cpu = time.perf_counter(), time.process_time()
    opt = TrajectoryOptimizer(options=PlannerOptions(force_model=name))
    build = {"wall_s": time.perf_counter() - tic, "cpu_s": time.process_time() - cpu}
    rows = []
    for soil in soils:
        for _ in range(repeats):
            opt.reset_warm_start()
            tic, cpu = time.perf_counter(), time.process_time()
            plan = opt.solve(soil, pile, start, duration)
            wall, cpu = time.perf_counter() - tic, time.process_time() - cpu
            check = verify_plan(plan, soil, pile, opt.bucket, opt.loader, opt.options)
            rows.append({"soil": soil, "wall_s": wall, "cpu_s": cpu, "status": plan.status,
                         "iterations": plan.iterations, "check_ok": check.ok, "fill": check.fill,
                         "carved": check.carved, "energy_J": check.energy})
    return {"build": build, "plans": rows}


def _median(rows: list[dict[str, Any]], key: str) -> float:
    return float(statistics.median(r[key] for r in rows))


def run(args: argparse.Namespace) -> dict[str, Any]:
    from wheelloader.estimator import FORCE_MODELS

    names = list(FORCE_MODELS)
    load_before = os.getloadavg()
    steps: dict[str, list[float]] = {n: [] for n in names}
    for _ in range(args.rounds):
        for name in names:
            steps[name].append(env_step_seconds(name, args.steps, args.seed))
    plans = {name: cold_plans(name, args.soils, args.repeats) for name in names}
    load_after = os.getloadavg()
    base_step = min(steps["fee"])
    base_plan = _median(plans["fee"]["plans"], "cpu_s")
    models = {}
    for name in names:
        rows = plans[name]["plans"]
        models[name] = {
            "env_step_cpu_us": 1e6 * min(steps[name]), "env_step_rounds_us": [1e6 * s for s in steps[name]],
            "env_step_ratio": min(steps[name]) / base_step,
            "plan_cold_cpu_median_s": _median(rows, "cpu_s"), "plan_cold_wall_median_s": _median(rows, "wall_s"),
            "plan_cold_ratio": _median(rows, "cpu_s") / base_plan,
            "plan_cold_cpu_mean_s": float(np.mean([r["cpu_s"] for r in rows])),
            "plan_cold_cpu_median_by_soil_s": {s: _median([r for r in rows if r["soil"] == s], "cpu_s")
                                               for s in args.soils},
            "plan_iterations_median": _median(rows, "iterations"),
            "plans_passing_check": sum(r["check_ok"] for r in rows), "plans": len(rows),
            "fill_median": _median(rows, "fill"), "carved_median": _median(rows, "carved"),
            "nlp_build": plans[name]["build"], "plan_rows": rows,
        }
        models[name]["env_step_met"] = models[name]["env_step_ratio"] <= STEP_LIMIT
        models[name]["plan_cold_met"] = models[name]["plan_cold_ratio"] <= PLAN_LIMIT
    return {"benchmark": "force_model_costs", "settings": vars(args), "machine": machine_info(),
            "load_before": load_before, "load_after": load_after, "models": models}


def table(results: dict[str, Any]) -> str:
    """The markdown table of ``results`` (one row per force model)."""
    soils = results["settings"]["soils"]
    lines = ["| force model | env step (CPU) | vs fee | cold plan (CPU, median) | vs fee | mean | by soil ("
             + ", ".join(soils) + ") | IPOPT iterations (median) | plans passing the check | fill (median) "
             "| carved (median) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, m in results["models"].items():
        by_soil = ", ".join(f"{v:.2f}" for v in m["plan_cold_cpu_median_by_soil_s"].values())
        lines.append(f"| {name} | {m['env_step_cpu_us']:.1f} us | {m['env_step_ratio']:.2f}x | "
                     f"{m['plan_cold_cpu_median_s']:.2f} s | {m['plan_cold_ratio']:.2f}x | "
                     f"{m['plan_cold_cpu_mean_s']:.2f} s | {by_soil} s | "
                     f"{m['plan_iterations_median']:.0f} | {m['plans_passing_check']}/{m['plans']} | "
                     f"{m['fill_median']:.3f} m³ | {m['carved_median']:.3f} m³ |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/force_model_costs", help="output directory")
    parser.add_argument("--soils", nargs="+", default=None, help="soil presets of the cold plans "
                        "(default gravel sand dirt; --quick gravel)")
    parser.add_argument("--repeats", type=int, default=None, help="cold plans per soil (default 3; --quick 1)")
    parser.add_argument("--steps", type=int, default=None, help="env steps per round (default 20000; --quick 5000)")
    parser.add_argument("--rounds", type=int, default=3, help="env rounds; the best counts (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the env's actions and resets")
    parser.add_argument("--quick", action="store_true", help="1 soil, 1 repeat, 5000 steps")
    args = parser.parse_args(argv)
    args.soils = args.soils or (["gravel"] if args.quick else ["gravel", "sand", "dirt"])
    args.repeats = args.repeats or (1 if args.quick else 3)
    args.steps = args.steps or (5000 if args.quick else 20000)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = run(args)
    (out / "results.json").write_text(json.dumps(to_jsonable({**results, "settings": {**vars(args), "out": None}}),
                                                 indent=1) + "\n")
    (out / "table.md").write_text(table(results))
    print(table(results))
    print(f"load average {results['load_before']} -> {results['load_after']}")
    return results


if __name__ == "__main__":
    main()
