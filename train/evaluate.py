"""Compare trained SB3 policies with the MPC planner, the fixed Bezier paths and a random policy.

Every policy runs on the plant (``wheelloader/BucketLoading-v0`` with a
fixed hidden soil) for every soil in ``--soils`` and every env seed in
``--seeds``: the same start poses and sensor noise for all policies. Per
policy: return, bucket fill, energy (work on soil plus payload lifting),
energy per m^3 (total energy / total fill), stalls, constraint violations
(steps outside the force model's validity domain, steps above the soft
force limit), overall and per soil.

Writes into ``--out`` (default ``results/evaluate``): ``evaluation.json``
(machine info, settings, per-policy summaries and raw episodes),
``evaluation.md`` (the summary table) and ``learning_curve.png`` (the
training runs' learning curves with the baselines' levels).

Usage::

    python train/evaluate.py --ppo results/ppo_randomized/model.zip --ppo results/ppo_twin/model.zip \
        --sac results/sac_randomized/model.zip --out results/evaluate
    python train/evaluate.py --rllib results/rllib_ppo/checkpoint --out results/evaluate_rllib   # RLlib PPO
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from common import int_list, machine_info, set_torch_threads, str_list, write_json
from policies import PathPolicy, RandomPolicy, load_rllib, load_sb3, mpc_policy
from rollouts import evaluate, summarize

_COLUMNS = (("return", "return", "{:.3f}"), ("fill", "fill_fraction", "{:.3f}"), ("energy [kJ]", "energy_J", None),
            ("energy/m^3 [kJ/m^3]", "energy_per_m3_J", None), ("stall rate", "stall_rate", "{:.2f}"),
            ("validity viol. [steps]", "validity_violations", "{:.1f}"),
            ("force-limit viol. [steps]", "force_limit_violations", "{:.1f}"), ("steps", "steps", "{:.0f}"))


def build_parser() -> argparse.ArgumentParser:
    """Command-line arguments."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ppo", type=Path, action="append", default=[], help="PPO model.zip (repeatable)")
    parser.add_argument("--sac", type=Path, action="append", default=[], help="SAC model.zip (repeatable)")
    parser.add_argument("--rllib", type=Path, action="append", default=[],
                        help="RLlib PPO checkpoint directory of train/rllib_ppo.py, OUT/checkpoint (repeatable)")
    parser.add_argument("--soils", type=str_list, default="all", help="plant soils, comma-separated or 'all'")
    parser.add_argument("--seeds", type=int_list, default="2000-2004", help="env seeds, e.g. 2000-2004 or 1,2,3")
    parser.add_argument("--mpc", action=argparse.BooleanOptionalAction, default=True,
                        help="include the MPC planner (skipped with a message if wheelloader.planner has none)")
    parser.add_argument("--mpc-seeds", type=int_list, default=None,
                        help="env seeds for the MPC planner only (default: --seeds); the MPC is the "
                             "slowest policy by far, so the full run gives it fewer")
    parser.add_argument("--bezier", type=int_list, default="1-4", help="fixed paper paths to include (1-4)")
    parser.add_argument("--random", action=argparse.BooleanOptionalAction, default=True,
                        help="include the random policy")
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=Path("results/evaluate"), help="output directory")
    parser.add_argument("--replot", action="store_true",
                        help="only rewrite evaluation.md and learning_curve.png from OUT/evaluation.json")
    return parser


def _fmt(value, fmt) -> str:
    if value is None:
        return "n/a"
    if fmt is None:
        return f"{value / 1000.0:.1f}"
    return fmt.format(value)


def markdown_table(results: dict, summaries: dict | None = None) -> str:
    """Overall summary of every policy as a Markdown table (``summaries``: name -> summary, default the
    overall ones); a policy run on fewer episodes than the most has its episode count in its name."""
    summaries = summaries or {name: res["overall"] for name, res in results.items()}
    most = max((s.get("episodes", 0) for s in summaries.values()), default=0)
    head = "| policy | " + " | ".join(c[0] for c in _COLUMNS) + " |"
    rule = "|---" * (len(_COLUMNS) + 1) + "|"
    rows = [head, rule]
    for name, s in summaries.items():
        n = s.get("episodes", most)
        label = name if n == most else f"{name} ({n} episode{'s' * (n != 1)})"
        rows.append(f"| {label} | " + " | ".join(_fmt(s.get(key), fmt) for _, key, fmt in _COLUMNS) + " |")
    return "\n".join(rows) + "\n"


def matched_summaries(results: dict, seeds: list[int]) -> dict:
    """Every policy's overall summary restricted to the episodes with env seeds in ``seeds``."""
    keep = set(seeds)
    return {name: summarize([e for e in res["episodes"] if e["seed"] in keep]) for name, res in results.items()}


def per_soil_table(results: dict, key: str = "fill_fraction", fmt: str = "{:.2f}") -> str:
    """``key`` per policy (rows) and soil (columns) as a Markdown table."""
    soils = list(next(iter(results.values()))["per_soil"]) if results else []
    rows = ["| policy | " + " | ".join(soils) + " |", "|---" * (len(soils) + 1) + "|"]
    for name, res in results.items():
        rows.append(f"| {name} | " + " | ".join(_fmt(res["per_soil"][s].get(key), fmt) for s in soils) + " |")
    return "\n".join(rows) + "\n"


def write_outputs(report: dict, out: Path) -> None:
    """``evaluation.md`` (tables) and ``learning_curve.png`` (the runs' learning curves read from their
    ``learning_curve.json`` next to the models, with the baselines' evaluation means) from a report."""
    results = report["results"]
    table = (f"Overall ({len(report['soils'])} soils x {len(report['seeds'])} seeds)\n\n" + markdown_table(results)
             + "\nFill per soil\n\n" + per_soil_table(results) + "\nReturn per soil\n\n"
             + per_soil_table(results, "return", "{:.3f}"))
    mpc_seeds = report.get("seeds_by_policy", {}).get("mpc")
    if mpc_seeds is not None and set(mpc_seeds) != set(report["seeds"]):
        table += (f"\nOn the MPC planner's seeds only ({len(report['soils'])} soils x seeds "
                  f"{', '.join(map(str, mpc_seeds))}: the same episodes for every policy)\n\n"
                  + markdown_table(results, matched_summaries(results, mpc_seeds)))
    (out / "evaluation.md").write_text(table)
    print(table, flush=True)
    curves = {}
    for name, run in report["runs"].items():
        curve = Path(run["model"]).parent / "learning_curve.json"
        if curve.exists():
            curves[name] = json.loads(curve.read_text())
    if curves:
        from curves import plot_learning_curves  # needs stable-baselines3 (its callback lives there too)

        base = {k: v["overall"] for k, v in results.items() if not k.startswith(("ppo", "sac"))}
        worst = min((k for k in base if k.startswith("bezier")), key=lambda k: base[k]["return"], default=None)
        most = max(b["episodes"] for b in base.values())
        shown = {(f"{k} (evaluation mean)" if base[k]["episodes"] == most
                  else f"{k} (evaluation mean, {base[k]['episodes']} episodes)"): base[k]
                 for k in ("random", "mpc") if k in base}
        if worst is not None:
            shown[f"{worst} (worst path, evaluation mean)"] = base[worst]
        plot_learning_curves(curves, out / "learning_curve.png", shown)


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, evaluate, write JSON, Markdown and the learning-curve PNG."""
    args = build_parser().parse_args(argv)
    out: Path = args.out
    if args.replot:
        write_outputs(json.loads((out / "evaluation.json").read_text()), out)
        return 0
    set_torch_threads(args.torch_threads)
    out.mkdir(parents=True, exist_ok=True)
    policies = []
    runs: dict[str, dict] = {}
    for algo, paths in (("ppo", args.ppo), ("sac", args.sac)):
        for path in paths:
            cfg_file = path.parent / "config.json"
            setup = json.loads(cfg_file.read_text()).get("setup", {}) if cfg_file.exists() else {}
            folder = path.parent.name
            name = folder if folder.startswith(algo + "_") else f"{algo}_{setup.get('setup', folder)}"
            while name in runs:
                name += "'"
            policies.append(load_sb3(path, name))
            runs[name] = {"model": str(path), "setup": setup}
    for path in args.rllib:
        folder = path.parent.name if path.name == "checkpoint" else path.name
        name = folder if folder.startswith("rllib") else f"rllib_{folder}"
        while name in runs:
            name += "'"
        policies.append(load_rllib(path, name))
        runs[name] = {"model": str(path), "setup": {"algo": "rllib ppo"}}
    skipped: list[str] = []
    if args.mpc:
        mpc = mpc_policy()
        if mpc is None:
            msg = "mpc: skipped, wheelloader.planner offers no env policy (make_env_policy)"
            print(msg, flush=True)
            skipped.append(msg)
        else:
            policies.append(mpc)
    for k in args.bezier:
        if not 1 <= k <= 4:
            raise SystemExit(f"--bezier: paths are numbered 1-4, got {k}")
        policies.append(PathPolicy(k - 1))
    if args.random:
        policies.append(RandomPolicy())
    print(f"evaluating {len(policies)} policies on {len(args.soils)} soils x {len(args.seeds)} seeds", flush=True)
    t0 = time.perf_counter()
    seeds_by_policy = {"mpc": args.mpc_seeds} if args.mpc_seeds is not None else {}
    if seeds_by_policy:
        print(f"MPC planner on seeds {args.mpc_seeds} only", flush=True)
    results = evaluate(policies, args.soils, args.seeds, progress=True, seeds_by_policy=seeds_by_policy)
    report = {"machine": machine_info(), "soils": args.soils, "seeds": args.seeds, "skipped": skipped,
              "seeds_by_policy": seeds_by_policy, "runs": runs,
              "results": results, "wall_s": time.perf_counter() - t0}
    write_json(out / "evaluation.json", report)
    write_outputs(report, out)
    print(f"wrote {out / 'evaluation.json'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
