"""Cycle-to-cycle adaptation benchmark: does calibrating between cycles pay off?

Runs the dig -> calibrate -> predict -> plan loop for many seeds x soils x
pile states, with soil drift between cycles and truths beyond the model
(compaction with depth, rate-dependent resistance, stones), and compares in
one run:

(a) ``fixed``  : fixed Bezier path, nominal parameters;
(b) ``ours``   : calibrate (default method on the last ``--window`` cycles, warm start) + predict + plan;
(c) ``oracle`` : plan with the plant's true (drifting) soil;
(d) ``paper``  : the paper's multi-stage calibrator in the same loop;
(e) ``rl``     : a trained SB3 policy, when ``--rl-policy`` is given.

Metrics per strategy: next-cycle force prediction RMSE (cycles >= 2), fill,
energy per m^3, stalls, validity-domain violations, time between cycles.

Usage::

    python benchmarks/adaptation.py --out results/adaptation            # full run
    python benchmarks/adaptation.py --quick --out /tmp/adaptation        # smoke run
    python benchmarks/adaptation.py --plant mpm --out DIR                # the loop in the MPM continuum
                                                                         # (runs benchmarks/plant_adaptation.py)
    python benchmarks/adaptation.py --ray off --out results/adaptation   # serial, without Ray

Each loop (soil x pile x seed x strategy) is one unit of :mod:`wheelloader.sweep`: ``--ray local`` (the
default with Ray installed) runs them as Ray tasks on this machine, ``--ray auto`` / ``--ray ray://HOST:10001``
on a cluster, ``--ray off`` one after the other; the tables are the same (times aside).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy: small dense fits
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from wheelloader.arguments import add_planner_physics_arguments, planner_physics  # noqa: E402
from wheelloader.estimator.synthetic import perturbed_preset  # noqa: E402
from wheelloader.provenance import commit_label, machine_info  # noqa: E402
from wheelloader.ray_mode import add_ray_arguments  # noqa: E402

SOILS = ("gravel", "dirt", "modified_sand")
PILES = {"trapezoid 30 deg": {"shape": "trapezoid"},
         "trapezoid 35 deg": {"shape": "trapezoid", "angle": math.radians(35.0)}}
TRUTH = {"compaction": 0.5, "rate_resistance": 1.0e4, "stone_rate": 0.5, "stone_force": 3000.0, "drift": 0.05}


def _strategy_names(args: argparse.Namespace) -> list[str]:
    names = ["fixed", "ours", "oracle", "paper"] + (["rl"] if args.rl_policy else [])
    if args.strategies:
        unknown = sorted(set(args.strategies) - set(names))
        if unknown:
            raise SystemExit(f"--strategies: unknown {unknown}; choose from {names}")
        names = [n for n in names if n in args.strategies]
    return names


def _ours_options(args: argparse.Namespace) -> dict[str, Any]:
    """Keyword arguments of strategy ``ours`` from the command line (only those given)."""
    out: dict[str, Any] = {}
    if args.window is not None:
        out["window"] = args.window
    if args.forgetting is not None:
        out["forgetting"] = args.forgetting
    out["keep_untrustworthy"] = args.keep_untrustworthy  # default True: adopt every converged fit
    if args.carried_load or args.slip_friction or args.failure_angle != "min_n_gamma":
        from wheelloader.estimator import ModelOptions

        out["options"] = ModelOptions(carried_load=args.carried_load, slip_friction=args.slip_friction,
                                      failure_angle=args.failure_angle)
    if args.fill != "log":
        out["fill"] = args.fill
    if args.force_model != "fee":
        out["force_model"] = args.force_model
    return out


def main(argv: list[str] | None = None) -> int:
    import subprocess
    import sys

    from wheelloader.references import PLANT_NAMES

    argv = sys.argv[1:] if argv is None else list(argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", choices=PLANT_NAMES, default=None,
                        help="close the loop in this reference plant instead of the drifting FEE env below: runs "
                             "benchmarks/plant_adaptation.py --plant PLANT with the other arguments, whose options "
                             "`adaptation.py --plant PLANT --help` lists (--soils, --resolution, --threads, "
                             "--fill-limit, --stale, --cycles-dir, --report besides --out, --seeds, --cycles, "
                             "--strategies, --quick, --no-planner, --failure-angle, the planner's physics and --ray); "
                             "the options below are then not used")
    parser.add_argument("--out", default="results/adaptation", help="output directory")
    parser.add_argument("--seeds", type=int, default=None,
                        help="seeds per soil and pile (default: 3; 1 with --quick); the seed table's median and "
                             "min-max are over them")
    parser.add_argument("--cycles", type=int, default=5, help="cycles per loop")
    parser.add_argument("--quick", action="store_true",
                        help="1 soil, 1 pile, 3 cycles and 1 seed unless --seeds is given (smoke run)")
    parser.add_argument("--no-planner", action="store_true", help="dig Bezier paths only (no CasADi planning)")
    parser.add_argument("--mpc", action="store_true", help="execute plans with the receding-horizon MPC")
    parser.add_argument("--rl-policy", help="a stable-baselines3 PPO .zip to include as strategy (e)")
    parser.add_argument("--window", type=int, default=None,
                        help="ours: calibrate on the last WINDOW cycles together (default: "
                             "wheelloader.adaptation.DEFAULT_WINDOW)")
    parser.add_argument("--forgetting", type=float, default=None,
                        help="ours: forgetting factor of the window's cycles (default: none, all weigh 1)")
    parser.add_argument("--reject-untrustworthy", action="store_false", dest="keep_untrustworthy",
                        help="ours: keep the previous fit when the new one is not trustworthy (default: adopt every "
                             "converged fit)")
    parser.add_argument("--keep-untrustworthy", action="store_true", dest="keep_untrustworthy",
                        help="ours: adopt every converged fit, trustworthy or not (the default)")
    parser.add_argument("--strategies", nargs="+", help="run only these strategies (default: all)")
    parser.add_argument("--prior", choices=("none", "nominal"), default=None,
                        help="ours: the calibration's prior; 'nominal' holds gamma, K and n softly at the loop's "
                             "soil preset (the plant's soil is its 10 %% perturbation) and fits cohesion, adhesion, "
                             "phi and delta (default: wheelloader.adaptation.DEFAULT_PRIOR)")
    parser.add_argument("--compare-prior", action="store_true",
                        help="also run ours with the other --prior, as strategy 'ours-PRIOR' (side by side)")
    add_ray_arguments(parser)
    parser.add_argument("--fill", choices=("log", "model"), default="log",
                        help="ours: bucket-load source of calibration and prediction (default: %(default)s)")
    parser.add_argument("--carried-load", action="store_true", help="ours: the opt-in carried-load term")
    parser.add_argument("--force-model", choices=("fee", "fee-payload"), default="fee",
                        help="ours: the force model it calibrates, predicts and plans with (the plant stays the "
                             "FEE env; default: %(default)s)")
    parser.add_argument("--slip-friction", action="store_true", help="ours: the opt-in slip-mobilised friction")
    add_planner_physics_arguments(parser, "every strategy that plans (PlannerOptions)")
    parser.add_argument("--failure-angle", choices=("min_n_gamma", "min_weight_force"), default="min_n_gamma",
                        help="ours: how the model picks beta* (default: the paper's min N_gamma; "
                             "min_weight_force: the opt-in least weight force)")
    plant_only = argparse.ArgumentParser(add_help=False)  # --plant first, so that --plant X --help is X's help
    plant_only.add_argument("--plant", choices=PLANT_NAMES, default=None)
    if plant_only.parse_known_args(argv)[0].plant is not None:
        # a separate script, run as a program (benchmarks import the package only, never each other)
        return subprocess.call([sys.executable, str(Path(__file__).with_name("plant_adaptation.py")), *argv])
    args = parser.parse_args(argv)

    from wheelloader.adaptation import DEFAULT_PRIOR, strategy_loop
    from wheelloader.estimator import preset
    from wheelloader.sweep import Unit, run_sweep

    if args.seeds is not None and args.seeds < 1:
        raise SystemExit(f"--seeds must be a positive integer, got {args.seeds}")
    soils, piles, seeds, cycles = SOILS, PILES, range(args.seeds or 3), args.cycles
    if args.quick:
        soils, piles, seeds, cycles = SOILS[:1], dict(list(PILES.items())[:1]), range(args.seeds or 1), 3
    planner = None if args.no_planner else "mpc" if args.mpc else "plan"
    prior = args.prior or DEFAULT_PRIOR
    other = "none" if prior == "nominal" else "nominal"
    names = _strategy_names(args)
    if args.compare_prior and "ours" in names:
        names.insert(names.index("ours") + 1, f"ours-{other}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    # one unit of work = one soil x pile x seed x strategy loop; the table is built in this (submission) order
    keys, units = [], []
    for soil_name in soils:
        for pile_name, pile_kwargs in piles.items():
            for seed in seeds:
                hidden = perturbed_preset(soil_name, seed)
                for name in names:
                    # the prior is centred on the preset the loop names; the plant digs its perturbation
                    mine = {**_ours_options(args), "prior": prior, "prior_soil": preset(soil_name)}
                    if name.startswith("ours-"):
                        mine.update(prior=other, name=name)
                    keys.append({"soil": soil_name, "pile": pile_name, "seed": seed})
                    units.append(Unit(strategy_loop, {"soil": hidden, "pile": pile_kwargs, "truth": TRUTH,
                                                      "strategy": "ours" if name.startswith("ours") else name,
                                                      "cycles": cycles, "seed": seed,
                                                      "planner": planner, "rl_policy": args.rl_policy,
                                                      "ours_options": mine,
                                                      **planner_physics(args)},
                                      label=f"{soil_name:>13} | {pile_name} | seed {seed} | {name:>6}"))
    start = time.perf_counter()
    sweep = run_sweep(units, args.ray, ray_cpus=args.ray_cpus, describe=_describe, progress=_print)
    loops = sweep.values_or_raise()
    rows: list[dict[str, Any]] = [{**key, **r} for key, records in zip(keys, loops, strict=True) for r in records]
    summary = summarise(rows)
    result = {
        "benchmark": "adaptation",
        "setup": {"soils": list(soils), "piles": list(piles), "seeds": len(seeds), "cycles": cycles,
                  "truth_beyond_model": TRUTH, "plant_soil": "preset with 10 % log-normal perturbation per seed",
                  "planner": ("none (Bezier paths)" if planner is None
                              else "CasADi plan + MPC" if planner == "mpc" else "CasADi plan, tracked"),
                  "sensor_noise_N": 150.0,
                  "ours": {"window": window_used(args), "forgetting": args.forgetting,
                           "keep_untrustworthy": args.keep_untrustworthy, "fill": args.fill,
                           "carried_load": args.carried_load, "slip_friction": args.slip_friction,
                           "failure_angle": args.failure_angle, "prior": prior,
                           "prior_soil": "the loop's soil preset"},
                  "planner_cut_angle_deg": args.cut_angle, "planner_heel_clearance_m": args.heel_clearance,
                  "planner_end_blade_angle_deg": args.end_blade_angle,
                  "planner_curl_out_intervals": args.curl_out_intervals,
                  "planner_midpoints": args.midpoints},
        "summary": summary,
        "summary_by_seed": summarise_by_seed(rows),
        "rows": rows,
        "wall_time_s": time.perf_counter() - start,
        "sweep": sweep.summary(),
        "machine": machine_info(),
    }
    (out / "adaptation.json").write_text(json.dumps(result, indent=2, default=float))
    table = (format_summary(summary) + "\n\n" + format_seed_table(result["summary_by_seed"]) + "\n\n"
             + format_plan_passes(rows) + "\n\n" + provenance_line(result))
    (out / "adaptation.md").write_text(table + "\n")
    plot(rows, out / "adaptation.png")
    print()
    print(table)
    print(f"\nwrote {out / 'adaptation.json'}, {out / 'adaptation.md'}, {out / 'adaptation.png'}")
    return 0


def window_used(args: argparse.Namespace) -> int:
    """The window of the ``ours`` strategy in this run."""
    from wheelloader.adaptation import DEFAULT_WINDOW

    return DEFAULT_WINDOW if args.window is None else args.window


def _print(line: str) -> None:
    print(line, flush=True)


def _describe(records: list[dict[str, Any]]) -> str:
    return (f"fill {np.mean([r['fill_fraction'] for r in records]):4.0%}, "
            f"{np.mean([r['energy_per_m3'] for r in records]) / 1e3:6.1f} kJ/m^3")


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """Per-strategy aggregates over all soils, piles, seeds and cycles."""
    out: dict[str, dict[str, float]] = {}
    for name in dict.fromkeys(r["strategy"] for r in rows):
        mine = [r for r in rows if r["strategy"] == name]
        later = [r for r in mine if r["cycle"] >= 2]
        fill = sum(r["fill_m3"] for r in mine)
        energy = sum(r["energy_J"] for r in mine)
        between = [r["between_cycles_s"] for r in later]
        out[name] = {
            "cycles": len(mine),
            "prediction_rmse_percent_mean": float(np.mean([r["prediction_rmse_percent"] for r in later])),
            "prediction_rmse_N_mean": float(np.mean([r["prediction_rmse_N"] for r in later])),
            "fill_fraction_mean": float(np.mean([r["fill_fraction"] for r in mine])),
            "energy_per_m3_total": energy / fill if fill > 0 else math.inf,
            "stalls": int(sum(r["stalled"] for r in mine)),
            "validity_violation_steps": int(sum(r["validity_violations"] for r in mine)),
            "calibration_failures": int(sum(not r["calibration_ok"] for r in mine)),
            "plan_failures": int(sum(not r["plan_ok"] for r in mine)),
            "between_cycles_median_s": float(statistics.median(between)) if between else 0.0,
            "between_cycles_max_s": float(max(between)) if between else 0.0,
        }
    return out


#: The seed table's columns: (summary key, header, format, scale).
SEED_COLUMNS = (("prediction_rmse_percent_mean", "next-cycle F_R RMSE [%]", "{:.1f}", 1.0),
                ("fill_fraction_mean", "fill [%]", "{:.0f}", 100.0),
                ("energy_per_m3_total", "energy per m³ [kJ/m³]", "{:.1f}", 1e-3),
                ("plan_failures", "plan failures", "{:.0f}", 1.0))


def summarise_by_seed(rows: list[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """Per strategy and column of :data:`SEED_COLUMNS`: each seed's aggregate (over soils, piles and cycles, as
    :func:`summarise`), and their median, min and max: ``{strategy: {key: {"per_seed": [...], "median": ...,
    "min": ..., "max": ...}}}``."""
    seeds = sorted({r["seed"] for r in rows})
    per_seed = {seed: summarise([r for r in rows if r["seed"] == seed]) for seed in seeds}
    out: dict[str, dict[str, dict[str, float]]] = {}
    for name in dict.fromkeys(r["strategy"] for r in rows):
        out[name] = {}
        for key, *_ in SEED_COLUMNS:
            values = [float(per_seed[seed][name][key]) for seed in seeds]
            out[name][key] = {"seeds": seeds, "per_seed": values, "median": float(statistics.median(values)),
                              "min": min(values), "max": max(values)}
    return out


def format_seed_table(by_seed: dict[str, dict[str, dict[str, float]]]) -> str:
    """Markdown table: each strategy's headline figures as the median over seeds with the min–max beside it."""
    first = next(iter(by_seed.values()))
    seeds = first[SEED_COLUMNS[0][0]]["seeds"]
    lines = [f"Over seeds ({', '.join(map(str, seeds))}; each seed aggregated over soils, piles and cycles): "
             "median (min–max).", "",
             "| strategy | " + " | ".join(head for _, head, _, _ in SEED_COLUMNS) + " |", "|" + "---|" * 5]
    for name, cols in by_seed.items():
        cells = []
        for key, _, fmt, scale in SEED_COLUMNS:
            c = cols[key]
            cells.append(f"{fmt.format(c['median'] * scale)} ({fmt.format(c['min'] * scale)}–"
                         f"{fmt.format(c['max'] * scale)})")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def format_summary(summary: dict[str, dict[str, float]]) -> str:
    """Markdown table of the summary."""
    head = ("| strategy | next-cycle F_R RMSE | fill | energy per m³ | stalls | validity steps | "
            "calib. / plan failures | time between cycles (median / max) |")
    lines = [head, "|" + "---|" * 8]
    for name, s in summary.items():
        lines.append(f"| {name} | {s['prediction_rmse_percent_mean']:.1f} % ({s['prediction_rmse_N_mean']:.0f} N) | "
                     f"{s['fill_fraction_mean']:.0%} | {s['energy_per_m3_total'] / 1e3:.1f} kJ/m³ | {s['stalls']} | "
                     f"{s['validity_violation_steps']} | {s['calibration_failures']} / {s['plan_failures']} | "
                     f"{s['between_cycles_median_s']:.3f} / {s['between_cycles_max_s']:.3f} s |")
    return "\n".join(lines)


def format_plan_passes(rows: list[dict[str, Any]]) -> str:
    """Markdown table: plans used (they passed the NumPy check) out of cycles, per strategy and cycle index."""
    names = [n for n in dict.fromkeys(r["strategy"] for r in rows) if n not in ("fixed", "rl")]
    cycles = sorted({r["cycle"] for r in rows})
    lines = ["| plans that passed the NumPy check | " + " | ".join(f"cycle {c}" for c in cycles) + " | all |",
             "|" + "---|" * (len(cycles) + 2)]
    for name in names:
        cells = []
        for c in [*cycles, None]:
            sel = [r for r in rows if r["strategy"] == name and (c is None or r["cycle"] == c)]
            cells.append(f"{sum(bool(r['plan_ok']) for r in sel)} / {len(sel)}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def provenance_line(result: dict[str, Any]) -> str:
    """One italic line: command, commit, load and run time of this result."""
    machine = result["machine"]
    commit = commit_label(machine)
    load = machine.get("loadavg_1_5_15min")
    load_text = "/".join(f"{v:.1f}" for v in load) if load else "unknown"
    sweep = result.get("sweep") or {"mode": "off"}
    how = ("loops run one after the other" if sweep["mode"] == "off"
           else f"loops as Ray tasks ({sweep['mode']}, {sweep.get('workers')} CPUs)")
    return (f"*`python benchmarks/adaptation.py` at commit {commit}, {how}; {machine.get('cpu_count')} cores "
            f"({machine.get('cpu') or 'CPU'}), load average {load_text} at the end, {result['wall_time_s']:.0f} s. "
            "Tables are deterministic for the seeds; times depend on the machine and its load.*")


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["strategy"] for r in rows))
    cycles = sorted({r["cycle"] for r in rows})
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.8))
    for name in names:
        for ax, key, scale in ((axes[0], "prediction_rmse_percent", 1.0), (axes[1], "fill_fraction", 100.0),
                               (axes[2], "energy_per_m3", 1e-3)):
            means = [np.mean([r[key] for r in rows if r["strategy"] == name and r["cycle"] == c]) * scale
                     for c in cycles]
            ax.plot(cycles, means, "o-", label=name)
    for ax, label in zip(axes, ("next-cycle F_R RMSE [%]", "bucket fill [%]", "energy per m³ [kJ/m³]"), strict=True):
        ax.set_xlabel("cycle")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("cycle-to-cycle adaptation (mean over soils, piles and seeds)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
