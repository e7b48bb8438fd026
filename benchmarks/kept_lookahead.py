"""The kept-payload objective and the two-cycle look-ahead against greedy and the fixed path (#33 items 1-2).

Closes the loop in the FEE env plant (``FEEEnvPlant(keep_env=True)``, the drifting env with truths beyond the
model, as ``benchmarks/adaptation.py``) for these strategies, each on its own pile cycle after cycle:

* ``fixed``: the default Bezier path placed on the face;
* ``greedy``: ``ours`` with the default objective (carved fill against energy), one plan per cycle;
* ``kept``: ``ours`` with ``PlannerOptions(objective="kept_per_energy")`` (planner/kept.py);
* ``lookahead``: ``ours`` with the greedy objective, each plan chosen with the cycle after it in view by the
  fast look-ahead (planner/lookahead.py ``FAST``: greedy and a fill-limit-0.80 candidate warm-started from it
  within 20 IPOPT iterations, the next cycle scored with the geometric Bezier placement);
* ``lookahead_full``: the same with three candidates, each followed by the greedy plan of the next cycle
  (the first look-ahead, 294-360 IPOPT iterations between cycles).

Between cycles is measured in IPOPT iterations (from the plans' messages) and in the process's CPU seconds of
the strategy's calibration and plan (``time.process_time``; the wall seconds depend on the machine's load).

Every cycle is judged the same way: the kept soil is the payload model's kept fill of the soil the env's bucket
holds (``DEFAULT_PAYLOAD``; the env books carved soil), and the energy is the env's plus the lift of the kept
load from the path's end to the fixed path's end height (1.20 m). Paired: the fixed path is also dug on every
start pile of every other strategy (a fresh env, same soil and seed), so each pair differs only in the path.

Usage::

    nice -n 10 python benchmarks/kept_lookahead.py --out docs/results/kept_lookahead   # 2 soils x 2 seeds x 10
    python benchmarks/kept_lookahead.py --quick --out /tmp/kl                          # 1 x 1 x 2 (smoke)
    python benchmarks/kept_lookahead.py --report --out docs/results/kept_lookahead     # table from the JSON

Loops are saved one JSON per loop under ``OUT/loops`` and read back (resumable).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator.synthetic import perturbed_preset
from wheelloader.provenance import commit_label, load_label, machine_info

SOILS = ("gravel", "dirt")
STRATEGIES = ("fixed", "greedy", "kept", "lookahead", "lookahead_full")
#: The strategies run by default (``lookahead_full`` costs ~5 times greedy's planning).
DEFAULT_STRATEGIES = ("fixed", "greedy", "kept", "lookahead")
TRUTH = {"compaction": 0.5, "rate_resistance": 1.0e4, "stone_rate": 0.5, "stone_force": 3000.0, "drift": 0.05}
#: The volume the "cycles to move" column counts to [m^3 of kept soil].
MOVE_VOLUME = 0.5


def judge(fill_m3: float, energy_j: float, z_end: float, gamma: float) -> dict[str, float]:
    """One cycle judged by the user's measure: kept soil and energy with the lift to the fixed path's end."""
    from wheelloader.estimator import Bucket
    from wheelloader.estimator.force_models import DEFAULT_PAYLOAD
    from wheelloader.planner.kept import dump_height, evaluate

    terms = evaluate(fill_m3, energy_j, z_end, gamma, Bucket().capacity, DEFAULT_PAYLOAD, dump_height())
    return {"carved_m3": fill_m3, "kept_m3": terms.kept, "dig_J": energy_j, "lift_J": terms.lift_energy,
            "energy_J": terms.energy, "z_end": z_end}


def _strategy(name: str):
    from wheelloader.adaptation import NOMINAL_SOIL, FixedBezier, default_planner, make_strategy
    from wheelloader.estimator import preset

    if name == "fixed":
        return FixedBezier(preset(NOMINAL_SOIL))
    planner = default_planner(objective="kept_per_energy" if name == "kept" else "fill_energy",
                              lookahead={"lookahead": "fast", "lookahead_full": "full"}.get(name, False))
    return _cpu_timed(make_strategy("ours", planner, ours_options={"name": name}))


def _cpu_timed(strategy):
    """``strategy`` with the CPU seconds of each plan and calibration recorded in ``strategy.cpu_s`` (one entry
    per cycle: the calibration after the previous cycle plus this cycle's plan)."""
    plan, update = strategy.plan, strategy.update
    strategy.cpu_s, pending = [], [0.0]

    def timed_plan(pile):
        tic = time.process_time()
        out = plan(pile)
        strategy.cpu_s.append(pending[0] + time.process_time() - tic)
        pending[0] = 0.0
        return out

    def timed_update(log, truth):
        tic = time.process_time()
        out = update(log, truth)
        pending[0] = time.process_time() - tic
        return out

    strategy.plan, strategy.update = timed_plan, timed_update
    return strategy


def run_one(soil_name: str, seed: int, strategy: str, cycles: int) -> dict[str, Any]:
    """One loop and the fixed path dug on each of its start piles."""
    from wheelloader.adaptation import NOMINAL_SOIL, FixedBezier
    from wheelloader.estimator import Pile, preset
    from wheelloader.loop import run_loop
    from wheelloader.references import make_plant

    soil = perturbed_preset(soil_name, seed)
    plant = make_plant("fee-env", keep_env=True, truth=dict(TRUTH))
    chosen = _strategy(strategy)
    try:
        records, logs = run_loop(plant, chosen, Pile.trapezoid(), soil, cycles=cycles, seed=seed)
    finally:
        plant.close()
    cpu = getattr(chosen, "cpu_s", [math.nan] * len(records))
    rows = []
    for r, log, cpu_s in zip(records, logs, cpu, strict=True):
        row = {"cycle": r.cycle, "path": r.path, "planning_s": r.planning_s, "between_cycles_s": r.between_cycles_s,
               "between_cycles_cpu_s": cpu_s,
               "plan_ok": r.plan_ok, "plan_message": r.plan_message, "prediction_rmse_percent":
               r.prediction_rmse_percent, **judge(r.fill_m3, r.energy_J, float(log.path.z[-1]), soil.gamma)}
        if strategy != "fixed":  # the fixed path on this cycle's start pile (paired)
            fixed_plant = make_plant("fee-env", keep_env=True, truth=dict(TRUTH))
            try:
                fr, fl = run_loop(fixed_plant, FixedBezier(preset(NOMINAL_SOIL)), log.pile, soil, cycles=1,
                                  seed=seed)
            finally:
                fixed_plant.close()
            row["fixed_on_pile"] = judge(fr[0].fill_m3, fr[0].energy_J, float(fl[0].path.z[-1]), soil.gamma)
        rows.append(row)
    return {"soil": soil_name, "seed": seed, "strategy": strategy, "cycles": rows}


def loop_figures(loop: dict[str, Any]) -> dict[str, float]:
    """Energy per kept m^3, mean kept fill, cycles to move MOVE_VOLUME, and the paired fixed path's."""
    from wheelloader.estimator import Bucket

    cap = Bucket().capacity
    rows = loop["cycles"]
    kept = [c["kept_m3"] for c in rows]
    out = {"kJ_per_kept_m3": sum(c["energy_J"] for c in rows) / sum(kept) / 1e3,
           "kept_fill": statistics.fmean(kept) / cap,
           "cycles_to_move": next((i + 1 for i, v in enumerate(np.cumsum(kept)) if v >= MOVE_VOLUME), math.inf),
           "between_cycles_s_median": statistics.median(c["between_cycles_s"] for c in rows[1:] or rows)}
    cpu = [c["between_cycles_cpu_s"] for c in rows[1:] if "between_cycles_cpu_s" in c]
    if cpu and all(math.isfinite(v) for v in cpu):  # from cycle 2 (the first plan builds the NLPs)
        out["between_cycles_cpu_s_median"] = statistics.median(cpu)
    spent = [int(m.group(1) or m.group(2)) for c in rows
             if (m := PLAN_ITERATIONS.search(c["plan_message"])) is not None]
    if spent:  # the IPOPT iterations of the plan dug (of its solve and re-plans; not the look-ahead's others)
        out["plan_iterations_median"] = statistics.median(spent)
    if all("fixed_on_pile" in c for c in rows):
        fixed = [c["fixed_on_pile"] for c in rows]
        out["fixed_kJ_per_kept_m3"] = sum(f["energy_J"] for f in fixed) / sum(f["kept_m3"] for f in fixed) / 1e3
        out["fixed_kept_fill"] = statistics.fmean(f["kept_m3"] for f in fixed) / cap
        out["kept_cycles_ge_fixed"] = sum(c["kept_m3"] >= f["kept_m3"] - 1e-9 for c, f in zip(rows, fixed,
                                                                                           strict=True))
    return out


PLAN_ITERATIONS = re.compile(r"IPOPT (?:\S+ in (\d+) it\.|iterate \d+ of (\d+))")
CHOICE = re.compile(r"look-ahead chose (?P<name>.+?) \((?P<costs>.+?) kJ/m\^3 kept over two cycles; "
                    r"(?P<iterations>\d+) IPOPT it")


def lookahead_stats(loop: dict[str, Any]) -> dict[str, float]:
    """How often the look-ahead chose another candidate than greedy, and its predicted two-cycle gain [%]
    (greedy's predicted cost over the chosen one's, by the model the strategy planned with)."""
    chosen, gains, iterations = 0, [], []
    for c in loop["cycles"]:
        m = CHOICE.search(c["plan_message"])
        if m is None:
            continue
        iterations.append(int(m.group("iterations")))
        costs = dict(part.rsplit(" ", 1) for part in m.group("costs").split(", "))
        greedy, best = float(costs.get("greedy", "inf")), float(costs[m.group("name")])
        chosen += m.group("name") != "greedy"
        if math.isfinite(greedy) and math.isfinite(best):
            gains.append(100.0 * (1.0 - best / greedy))
    return {"non_greedy_choices": chosen, "cycles_weighed": len(gains),
            "ipopt_iterations_median": statistics.median(iterations) if iterations else math.nan,
            "predicted_gain_percent_median": statistics.median(gains) if gains else math.nan,
            "predicted_gain_percent_max": max(gains) if gains else math.nan,
            "next_cycle_error_percent_median": statistics.median(
                c["prediction_rmse_percent"] for c in loop["cycles"][2:]) if len(loop["cycles"]) > 2 else math.nan}


def table(loops: list[dict[str, Any]]) -> str:
    """The markdown table: per strategy, each loop's figures and the median over loops."""
    lines = ["| strategy | soil | seed | kJ/m^3 kept | kept fill | fixed on the same piles: kJ/m^3 kept | "
             "kept fill | cycles kept >= fixed | cycles to move 0.5 m^3 | between cycles (median s) | "
             "CPU s (median) | IPOPT it. (median) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for loop in loops:
        f = loop_figures(loop)
        fixed = (f"{f['fixed_kJ_per_kept_m3']:.1f} | {f['fixed_kept_fill']:.0%} | "
                 f"{f['kept_cycles_ge_fixed']}/{len(loop['cycles'])}") if "fixed_kJ_per_kept_m3" in f else "- | - | -"
        lines.append(f"| {loop['strategy']} | {loop['soil']} | {loop['seed']} | {f['kJ_per_kept_m3']:.1f} | "
                     f"{f['kept_fill']:.0%} | {fixed} | {f['cycles_to_move']} | {f['between_cycles_s_median']:.1f} | "
                     f"{_cell(f.get('between_cycles_cpu_s_median'), '.2f')} | {_cell(_iterations(loop), '.0f')} |")
    return "\n".join(lines)


def _cell(value: float | None, fmt: str) -> str:
    return "-" if value is None or not math.isfinite(value) else format(value, fmt)


def _iterations(loop: dict[str, Any]) -> float | None:
    """Median IPOPT iterations between cycles: the look-ahead's total where it weighed candidates, else the plan's."""
    if loop["strategy"].startswith("lookahead"):
        return lookahead_stats(loop)["ipopt_iterations_median"]
    return loop_figures(loop).get("plan_iterations_median")


def against_greedy(loops: list[dict[str, Any]]) -> str:
    """Each strategy's energy per kept m^3 relative to greedy on the same soil and seed (negative: better)."""
    by = {(lp["strategy"], lp["soil"], lp["seed"]): loop_figures(lp) for lp in loops}
    lines = ["| strategy | per loop: kJ/m^3 kept vs greedy | median | cycles to move vs greedy |", "|---|---|---|---|"]
    for name in STRATEGIES:
        if name == "greedy":
            continue
        gains, moves = [], []
        for (s, soil, seed), f in by.items():
            g = by.get(("greedy", soil, seed))
            if s == name and g is not None:
                gains.append(100.0 * (f["kJ_per_kept_m3"] / g["kJ_per_kept_m3"] - 1.0))
                a, b = f["cycles_to_move"], g["cycles_to_move"]
                moves.append(f"{a - b:+}" if math.isfinite(a) and math.isfinite(b) else f"{a} vs {b}")
        if gains:
            lines.append(f"| {name} | {', '.join(f'{v:+.1f} %' for v in gains)} | {statistics.median(gains):+.1f} % | "
                         f"{', '.join(moves)} |")
    return "\n".join(lines)


def plot(loops: list[dict[str, Any]], path: Path) -> None:
    """Energy per kept m^3 and kept fill per loop: each strategy beside the fixed path on the same piles."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_e, ax_k) = plt.subplots(1, 2, figsize=(11, 4))
    labels, energy, fixed_energy, kept, fixed_kept = [], [], [], [], []
    for loop in loops:
        f = loop_figures(loop)
        labels.append(f"{loop['strategy']}\n{loop['soil']} s{loop['seed']}")
        energy.append(f["kJ_per_kept_m3"])
        kept.append(100 * f["kept_fill"])
        fixed_energy.append(f.get("fixed_kJ_per_kept_m3", math.nan))
        fixed_kept.append(100 * f.get("fixed_kept_fill", math.nan))
    x = np.arange(len(labels))
    for ax, ours, fixed, unit in ((ax_e, energy, fixed_energy, "kJ per m^3 kept (lift to 1.20 m)"),
                                  (ax_k, kept, fixed_kept, "mean kept fill [% of nominal]")):
        ax.bar(x - 0.2, ours, 0.4, label="strategy")
        ax.bar(x + 0.2, fixed, 0.4, label="fixed path on the same piles")
        ax.set_xticks(x, labels, fontsize=6, rotation=90)
        ax.set_ylabel(unit)
    ax_e.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/kept_lookahead", help="output directory")
    parser.add_argument("--soils", nargs="+", default=list(SOILS))
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--only-seed", type=int, help="run only this seed (parallel processes on one --out)")
    parser.add_argument("--cycles", type=int, default=10)
    parser.add_argument("--strategies", nargs="+", choices=STRATEGIES, default=list(DEFAULT_STRATEGIES))
    parser.add_argument("--quick", action="store_true", help="1 soil, 1 seed, 2 cycles (smoke run)")
    parser.add_argument("--report", action="store_true", help="only rebuild the table from the saved loops")
    args = parser.parse_args(argv)
    soils, seeds, cycles = args.soils, range(args.seeds), args.cycles
    if args.quick:
        soils, seeds, cycles = soils[:1], range(1), 2
    if args.only_seed is not None:
        seeds = range(args.only_seed, args.only_seed + 1)
    out = Path(args.out)
    (out / "loops").mkdir(parents=True, exist_ok=True)
    started, before = time.perf_counter(), machine_info()
    loops = []
    for soil in soils:
        for seed in seeds:
            for name in args.strategies:
                path = out / "loops" / f"{soil}_seed{seed}_{name}_{cycles}.json"
                if path.exists():
                    loops.append(json.loads(path.read_text()))
                    continue
                if args.report:
                    continue
                tic = time.perf_counter()
                loop = run_one(soil, seed, name, cycles)
                loop["seconds"] = time.perf_counter() - tic
                path.write_text(json.dumps(loop, indent=1))
                loops.append(loop)
                print(f"{soil} seed {seed} {name}: {loop_figures(loop)} ({loop['seconds']:.0f} s)", flush=True)
    after = machine_info()
    summary = {"benchmark": "kept_lookahead", "commit": commit_label(before), "machine": before,
               "load_before": load_label(before), "load_after": load_label(after),
               "seconds": time.perf_counter() - started,
               "cycles": cycles, "soils": list(soils), "seeds": list(seeds),
               "loops": [{k: lp[k] for k in ("soil", "seed", "strategy")} | loop_figures(lp)
                         | (lookahead_stats(lp) if lp["strategy"].startswith("lookahead") else {}) for lp in loops]}
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str))
    text = table(loops) + "\n\n" + against_greedy(loops) + "\n"
    (out / "table.md").write_text(text)
    if loops:
        plot(loops, out / "kept_lookahead.png")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
