"""The adaptation loop closed on a plant that is not the model (``benchmarks/adaptation.py --plant mpm|dem``).

For each soil x seed, in one run: (a) ``fixed`` Bezier path with nominal parameters, (b) ``ours``
(calibrate on the cycle just dug, warm start; plan), (d) ``paper`` (the multi-stage calibrator in the same
loop), then (c) ``oracle``: one set of FEE parameters fitted afterwards to all of that soil's cycles of
(a), (b) and (d), planned with from the first cycle (a hindsight bound on what calibration can give in
this plant). Energy, fill and the next-cycle prediction error are measured by the plant for every
strategy alike (:mod:`wheelloader.loop`).

Each loop (soil x seed x strategy) is one unit of :mod:`wheelloader.sweep`: with Ray installed they run as
Ray tasks on this machine (``--ray local``, one per CPU; ``--threads`` Taichi threads each), on a cluster with
``--ray auto`` / ``--ray ray://HOST:10001``, or one after the other with ``--ray off``; the oracle's loops
start when all the others of its soil are done. The tables are the same whatever ran them (times aside).

Every cycle's log is saved (xz-compressed) under ``CYCLES/<soil>/seed<k>/<strategy>/`` as it finishes
(``--cycles-dir``, default ``OUT/cycles``); running the same command again resumes (a saved cycle is read when
its planned path is the same). The committed runs keep their saved cycles under ``data/results/<run>/cycles``
(data, not docs).

Usage::

    python benchmarks/adaptation.py --plant mpm --out docs/results/adaptation_mpm \\
        --cycles-dir data/results/adaptation_mpm/cycles                               # 2 soils x 2 seeds x 5
    python benchmarks/adaptation.py --plant mpm --quick --out /tmp/plant_quick          # 1 cycle, coarse grid
    python benchmarks/adaptation.py --plant dem --quick --out /tmp/plant_dem_quick      # Yade, CI's coarse spheres
    python benchmarks/adaptation.py --plant fee-env --out /tmp/plant_fee               # the same loop in the env

The DEM plant (:class:`wheelloader.references.dem.DEMPlant`, Yade from ``bash dem/install_yade.sh``) settles a
packing carved to each cycle's pile and scales its slab to the loop's bucket by geometric similarity
(cohesionless soils); ``--quick`` uses the CI scenario's coarse spheres.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from pathlib import Path
from typing import Any

from wheelloader.arguments import add_planner_physics_arguments, planner_physics
from wheelloader.estimator.force_models import FORCE_MODELS
from wheelloader.provenance import commit_label, load_label, machine_info
from wheelloader.ray_mode import add_ray_arguments
from wheelloader.references import PLANT_NAMES

STRATEGIES = ("fixed", "ours", "paper", "oracle", "rl_path", "rl_closed")
#: The strategies run by default (``rl_path`` and ``rl_closed`` need ``--rl-policy``).
DEFAULT_STRATEGIES = ("fixed", "ours", "paper", "oracle")


def plant_from_args(args: argparse.Namespace) -> Any:
    """The plant of the command line (:func:`wheelloader.references.make_plant`); ``--quick``: the DEM's CI
    scenario."""
    from wheelloader.references import make_plant

    if args.plant == "mpm":
        if args.taichi_threads is not None:  # Taichi runs this many threads; the lanes (and results): --threads
            from wheelloader.references.mpm import taichi_module

            taichi_module(args.taichi_threads)
        return make_plant("mpm", resolution=args.resolution, threads=args.threads)
    if args.plant == "dem":
        return make_plant("dem", scenario="ci" if args.quick else "default", threads=args.threads)
    return make_plant(args.plant)


def planned_fill_limit(plant: Any, setting: str) -> float | None:
    """The planner's fill limit (share of the nominal capacity): ``default`` the planner's (0.95); ``struck`` up to
    95 % of the plant's struck capacity where the plant has one (the MPM bucket's fill outline holds 0.135 of the
    nominal 0.2 m^3), else the planner's default; or the given number."""
    if setting == "default":
        return None
    if setting == "struck":
        struck = getattr(plant, "struck_capacity", None)
        if struck is None:
            return None
        from wheelloader.estimator import Bucket

        return round(0.95 * struck / Bucket().capacity, 4)
    try:
        value = float(setting)
    except ValueError:
        raise SystemExit(f"--fill-limit must be 'default', 'struck' or a number in (0, 1], got {setting!r}") from None
    if not 0.0 < value <= 1.0:
        raise SystemExit(f"--fill-limit must be 'default', 'struck' or a number in (0, 1], got {setting!r}")
    return value


def payload_from(source: str | None) -> dict[str, float] | None:
    """The payload state of ``--payload``: None (the model's default), or the fields of a JSON file: its
    ``"payload"`` (``benchmarks/transfer.py``'s ``transfer.json``: the recipe chosen on validation, with its curl
    gain) or the file itself (``PayloadOptions.to_dict``'s form)."""
    if source is None:
        return None
    from wheelloader.estimator import PayloadOptions

    try:
        data = json.loads(Path(source).read_text())
        fields = data.get("payload", data) if isinstance(data, dict) else data
        return PayloadOptions.from_dict(fields).to_dict()
    except (OSError, ValueError, TypeError, AttributeError) as exc:
        raise SystemExit(f"wheelloader: error: --payload {source}: {exc}") from None


def cycles_dir(args: argparse.Namespace) -> Path:
    """Where the saved cycles are: ``--cycles-dir``, else ``OUT/cycles``."""
    return Path(args.cycles_dir) if args.cycles_dir is not None else Path(args.out) / "cycles"


def run(args: argparse.Namespace) -> dict[str, Any]:
    from wheelloader.estimator import ModelOptions
    from wheelloader.loop import hindsight_parameters, plant_loop_unit
    from wheelloader.sweep import Unit, run_sweep

    plant = plant_from_args(args)
    saved = cycles_dir(args)
    started = time.perf_counter()
    fill_limit = planned_fill_limit(plant, args.fill_limit)
    args.fill_limit_used = fill_limit
    loop_kwargs = {"plant": plant, "cycles": args.cycles, "planner": not args.no_planner, "fill_limit": fill_limit,
                   "failure_angle": args.failure_angle, "objective": args.objective, "lookahead": args.lookahead,
                   "rl_policy": args.rl_policy, "prior": args.prior,
                   "descend_clearance": args.descend_clearance, "payload": payload_from(args.payload),
                   "force_model": args.force_model, "compiled": args.compiled, **planner_physics(args)}
    learning = [s for s in args.strategies if s != "oracle"]
    keys = [(soil, seed, name) for soil in args.soils for seed in range(args.seeds) for name in learning]
    units = [Unit(plant_loop_unit, {**loop_kwargs, "strategy": name, "soil": soil, "seed": seed, "stale": args.stale,
                                    "cache": saved / soil / f"seed{seed}" / name},
                  label=f"{soil} | seed {seed} | {name}", num_cpus=args.threads) for soil, seed, name in keys]
    # phase 1: every loop that learns (or does not) from its own cycles, as sweep units (Ray tasks when present)
    print(f"{len(units)} loops ({args.cycles} cycles each) on the {args.plant} plant, --ray {args.ray}", flush=True)
    loops = run_sweep(units, args.ray, ray_cpus=args.ray_cpus, progress=_print).values_or_raise()
    by_key = dict(zip(keys, loops, strict=True))
    oracles: dict[str, Any] = {}
    oracle_keys: list[tuple[str, int, str]] = []
    oracle_units = []
    if "oracle" in args.strategies:
        # phase 2: one set of FEE parameters fitted afterwards to all of the soil's cycles, then its loops
        for soil in args.soils:
            soil_logs = [lg for (s, _, _), loop in by_key.items() if s == soil for lg in loop["logs"]]
            if not soil_logs:
                continue
            params, how = hindsight_parameters(soil_logs, options=ModelOptions(failure_angle=args.failure_angle))
            oracles[soil] = {"params": params.to_dict(), "fitted": how}
            print(f"{soil}: oracle parameters: {how}", flush=True)
            for seed in range(args.seeds):
                oracle_keys.append((soil, seed, "oracle"))
                oracle_units.append(Unit(plant_loop_unit, {**loop_kwargs, "strategy": "oracle", "soil": soil,
                                                           "seed": seed, "oracle_params": params, "stale": "redig",
                                                           "cache": saved / soil / f"seed{seed}" / "oracle"},
                                         label=f"{soil} | seed {seed} | oracle", num_cpus=args.threads))
        if oracle_units:
            loops = run_sweep(oracle_units, args.ray, ray_cpus=args.ray_cpus, progress=_print).values_or_raise()
            by_key.update(zip(oracle_keys, loops, strict=True))
    rows: list[dict[str, Any]] = []
    for soil in args.soils:  # the table's order: soil, seed, strategy, cycle (whatever ran the loops)
        for seed in range(args.seeds):
            for name in args.strategies:
                if (soil, seed, name) in by_key:
                    rows += [dict(r, soil=soil, seed=seed) for r in by_key[(soil, seed, name)]["records"]]
    return {"benchmark": "plant_adaptation", "plant": args.plant, "settings": vars(args) | {"out": str(args.out)},
            "machine": machine_info(), "rows": rows, "oracle": oracles, "wall_s": time.perf_counter() - started,
            "metrics": {"energy": "work of the plant's bucket force along the path (loop, references.metrics)",
                        "fill": "plant's soil inside the bucket at the end",
                        "prediction": "F_R RMSE of the parameters planned with vs the plant's force filtered "
                                      "(sigma 0.1 s), % of mean |F_R| in soil"}}


def _kept_note(rows: list[dict[str, Any]]) -> str:
    """What the table says about saved cycles kept although the plan made now differs (``--stale keep``)."""
    kept = [r for r in rows if str(r.get("end", "")).startswith("kept saved cycle")]
    if not kept:
        return ""
    return (f" {len(kept)} of {len(rows)} cycles were kept from an earlier invocation although the plan made now "
            "differs (`--stale keep`: calibrations agree to the last bits, the planner's choice does not); "
            "each record's `end` gives the distance.")


def _print(line: str) -> None:
    print(line, flush=True)


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for name in STRATEGIES:
        sel = [r for r in rows if r["strategy"] == name]
        if not sel:
            continue
        energy = sum(r["energy_J"] for r in sel)
        fill = sum(r["fill_m3"] for r in sel)
        later = [r["prediction_rmse_percent"] for r in sel if r["cycle"] >= 2]
        from3 = [r["prediction_rmse_percent"] for r in sel if r["cycle"] >= 3]
        between = [r["between_cycles_s"] for r in sel if r["cycle"] >= 2]
        out[name] = {"cycles": len(sel), "energy_per_m3_kJ": energy / fill / 1e3 if fill > 0 else float("inf"),
                     "mean_fill_fraction": statistics.fmean(r["fill_fraction"] for r in sel),
                     "next_cycle_rmse_percent": statistics.median(later) if later else float("nan"),
                     "next_cycle_rmse_percent_from_cycle3": statistics.median(from3) if from3 else float("nan"),
                     "plans_passing": sum(1 for r in sel if r["plan_ok"]),
                     "median_between_cycles_s": statistics.median(between) if between else 0.0}
    return out


def lifted_to_common_height(rows: list[dict[str, Any]], cycles: Path | None) -> dict[str, Any] | None:
    """Energy per m³ of each strategy with its kept load lifted to the fixed Bézier path's end height.

    A plan may end lower than the fixed path (its tip just clear of the carved surface), so the plant's work
    along it lifts the load less; the loader lifts the rest afterwards. Here every cycle's energy gets the work
    of lifting what it kept from its end height to ``z_ref``, the highest end of the fixed path's cycles (a
    cycle ending above it is credited the difference): ``rho g V_kept (z_ref - z_end)``, with ``rho`` the
    continuum's density where the log has one, else the soil preset's. Read from the saved cycles
    (``cycles/SOIL/seedN/STRATEGY/cycleK.csv.xz``); None without fixed-path cycles or when a cycle is missing.
    """
    from wheelloader.estimator import preset
    from wheelloader.estimator.force_model import GRAVITY
    from wheelloader.saved_loops import load_saved_cycle

    if cycles is None or not any(r["strategy"] == "fixed" for r in rows):
        return None
    ends = []
    for r in rows:
        log = load_saved_cycle(Path(cycles) / r["soil"] / f"seed{r['seed']}" / r["strategy"], r["cycle"])
        if log is None:
            return None
        density = (log.metadata.get("continuum") or {}).get("density") or preset(r["soil"]).gamma
        ends.append((float(log.path.z[-1]), float(density)))
    z_ref = max(z for (z, _), r in zip(ends, rows, strict=True) if r["strategy"] == "fixed")
    per: dict[str, list[float]] = {}  # strategy -> [lifted energy, kept volume, sum of end heights, cycles]
    for (z_end, density), r in zip(ends, rows, strict=True):
        lift = density * GRAVITY * r["fill_m3"] * (z_ref - z_end)
        acc = per.setdefault(r["strategy"], [0.0, 0.0, 0.0, 0])
        acc[0] += r["energy_J"] + lift
        acc[1] += r["fill_m3"]
        acc[2] += z_end
        acc[3] += 1
    return {"z_ref_m": z_ref,
            "energy_per_m3_kJ": {n: a[0] / a[1] / 1e3 if a[1] > 0 else float("inf") for n, a in per.items()},
            "mean_end_height_m": {n: a[2] / a[3] for n, a in per.items()}}


def markdown(result: dict[str, Any], cycles: Path | None = None) -> str:
    """The run's tables; with ``cycles`` (the saved cycles' folder) also the energy with the kept load lifted
    to the fixed path's end height (:func:`lifted_to_common_height`)."""
    summary = summarise(result["rows"])
    s = result["settings"]
    common = lifted_to_common_height(result["rows"], cycles)
    lifted = (" energy per m³, load lifted to the fixed path's end |" if common else "")
    lines = [f"| strategy ({result['plant']} plant) | cycles | energy per m³ |{lifted} mean fill | next-cycle F_R "
             "error (median, cycles ≥ 2 / ≥ 3) | plans passing the check | between cycles (median) |",
             "|---|---|---|---|---|---|---|" + ("---|" if common else "")]
    for name, m in summary.items():
        passing = "– (Bézier)" if name == "fixed" else f"{m['plans_passing']}/{m['cycles']}"
        cell = (f" {common['energy_per_m3_kJ'][name]:.1f} kJ/m³ (ends at {common['mean_end_height_m'][name]:.2f} m) |"
                if common else "")
        lines.append(f"| {name} | {m['cycles']} | {m['energy_per_m3_kJ']:.1f} kJ/m³ |{cell} "
                     f"{m['mean_fill_fraction']:.0%} | "
                     f"{m['next_cycle_rmse_percent']:.1f} / {m['next_cycle_rmse_percent_from_cycle3']:.1f} % | "
                     f"{passing} | {m['median_between_cycles_s']:.2f} s |")
    lines += ["", "| per cycle: kJ/m³ (fill) | " + " | ".join(f"cycle {k}" for k in range(1, s["cycles"] + 1)) + " |",
              "|---|" + "---|" * s["cycles"]]
    for name in summary:
        cells = []
        for k in range(1, s["cycles"] + 1):
            sel = [r for r in result["rows"] if r["strategy"] == name and r["cycle"] == k]
            energy, fill = sum(r["energy_J"] for r in sel), sum(r["fill_m3"] for r in sel)
            cells.append(f"{energy / fill / 1e3:.0f} ({fill / len(sel) / 0.2:.0%})" if sel and fill > 0 else "–")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    load = load_label(result["machine"])
    lines += ["", f"*`python benchmarks/adaptation.py --plant {result['plant']}` ({', '.join(s['soils'])}; "
              f"{s['seeds']} seed(s); {s['cycles']} cycles; "
              + (f"MPM dx {s['resolution']} m" if result["plant"] == "mpm" else
                 "DEM " + ("CI scenario's coarse spheres" if s.get("quick") else "default scenario")
                 if result["plant"] == "dem" else "FEE env")
              + ("" if s.get("failure_angle", "min_n_gamma") == "min_n_gamma" else
                 f"; ours and oracle with `--failure-angle {s['failure_angle']}`")
              + ("" if s.get("cut_angle") is None else f"; planner with `--cut-angle {s['cut_angle']:g}`")
              + ("" if s.get("heel_clearance") is None else f"; `--heel-clearance {s['heel_clearance']:g}`")
              + ("" if s.get("end_blade_angle") is None else f"; `--end-blade-angle {s['end_blade_angle']:g}`")
              + ("" if not s.get("curl_out_intervals") else f" `--curl-out-intervals {s['curl_out_intervals']}`")
              + ("" if s.get("midpoints") is None else f"; `--midpoints {s['midpoints']}`")
              + ("" if s.get("objective", "fill_energy") == "fill_energy" else f"; `--objective {s['objective']}`")
              + ("" if not s.get("lookahead") else "; `--lookahead`" + ("" if s["lookahead"] is True
                                                                           else f" {s['lookahead']}"))
              + ("" if s.get("prior", "none") == "none" else f"; ours with `--prior {s['prior']}`")
              + ("" if s.get("force_model", "fee") == "fee" else f"; ours with `--force-model {s['force_model']}`")
              + ("" if s.get("descend_clearance") is None else f"; `--descend-clearance {s['descend_clearance']:g}`")
              + ("" if s.get("payload") is None else f"; `--payload {s['payload']}`")
              + ("" if s.get("fill_limit_used") is None else f", planned fill ≤ {s['fill_limit_used']:.0%} of 0.2 m³")
              + ") at "
              f"{commit_label(result['machine'])}; loops run with `--ray {s.get('ray', 'off')}`; the last "
              f"invocation took {result['wall_s'] / 60:.0f} min (cycles "
              f"saved by earlier ones are read, not dug again), load average at its end {load}. Energy = plant-"
              "measured work / plant-measured fill over all cycles; fill in % of the nominal 0.2 m³; fixed paths "
              "are Bézier paths (not checked); a plan that fails the check falls back to the Bézier path placed "
              "by the model."
              + ("" if not common else
                 f" 'Load lifted to the fixed path's end': each cycle's energy plus the work of lifting what it kept "
                 f"from its end height to {common['z_ref_m']:.2f} m, where the fixed path ends (a plan that ends "
                 "lower lifts its load less along the path; the loader lifts the rest afterwards; density the "
                 "continuum's, else the soil preset's).")
              + _kept_note(result["rows"]) + "*"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--plant", choices=PLANT_NAMES, default="mpm",
                        help="the plant that digs (wheelloader.references.make_plant; default: %(default)s)")
    parser.add_argument("--out", default="results/adaptation_mpm", help="output directory")
    parser.add_argument("--cycles-dir", default=None, metavar="DIR",
                        help="folder of the saved cycles (the resume cache; default OUT/cycles)")
    parser.add_argument("--soils", nargs="+", default=["gravel", "sand"], help="soil presets of the plant")
    parser.add_argument("--seeds", type=int, default=2, help="plant seeds per soil (packing jitter)")
    parser.add_argument("--cycles", type=int, default=5, help="cycles per loop")
    parser.add_argument("--strategies", nargs="+", default=list(DEFAULT_STRATEGIES), choices=STRATEGIES,
                        help="loops to run (default %(default)s); rl_path: a trained policy's path, rolled out in the "
                             "FEE env of the nominal soil on each cycle's pile, dug in the plant (open loop); "
                             "rl_closed: the policy acting on the plant's state every control step (MPM plant)")
    parser.add_argument("--rl-policy", default=None, metavar="ZIP",
                        help="the trained PPO policy (model.zip of train/ppo.py) of the rl_path and rl_closed "
                             "strategies; rolled out in the env of its config.json's force model")
    parser.add_argument("--resolution", type=float, default=0.02, help="MPM grid spacing [m] (verified: 0.02)")
    parser.add_argument("--threads", type=int, default=1, help="Taichi CPU threads")
    parser.add_argument("--taichi-threads", type=int, default=None, metavar="N",
                        help="MPM plant: the CPU threads Taichi runs (default --threads); the results depend on "
                             "--threads (the lanes the particles are split into) only")
    parser.add_argument("--no-planner", action="store_true", help="dig Bezier paths only")
    parser.add_argument("--failure-angle", choices=("min_n_gamma", "min_weight_force"), default="min_n_gamma",
                        help="beta* rule of ours' and the oracle's model (calibration, prediction, planner); "
                             "default the paper's min N_gamma; paper and fixed are unaffected")
    parser.add_argument("--fill-limit", default="default", metavar="SHARE",
                        help="largest planned fill, share of the nominal capacity: 'default' (the planner's 0.95), "
                             "'struck' (95 %% of the plant's struck capacity where it has one: MPM 0.64) or a number")
    add_planner_physics_arguments(parser, "for every strategy that plans")
    parser.add_argument("--objective", choices=("fill_energy", "kept_per_energy"), default="fill_energy",
                        help="the planner's objective for every strategy that plans: carved fill against energy "
                             "(default) or energy per m^3 of kept soil with the lift to the dump height (#33)")
    parser.add_argument("--lookahead", nargs="?", const=True, default=False, choices=("full", "fast", "kept"),
                        help="choose each plan with the cycle after it in view (planner/lookahead.py; bare: the "
                             "full setting; kept: its candidates for the kept objective)")
    parser.add_argument("--stale", choices=("error", "redig", "keep"), default="error",
                        help="a saved cycle dug along another path than the one planned now (other code, settings "
                             "or machine: plans can change with the last bits of the calibrated parameters): stop "
                             "(default), dig it again, or keep it as the cycle dug (its distance to the plan made "
                             "now is recorded); the oracle's loops always dig such a cycle again (its parameters "
                             "are fitted anew to the soil's cycles: a saved cycle may have been planned with others)")
    parser.add_argument("--prior", choices=("none", "nominal", "held"), default="none",
                        help="ours' calibration prior at its nominal soil (wheelloader.loop_prior.LOOP_PRIORS): none "
                             "(default), nominal (gamma, K, n held softly) or held (all seven held softly)")
    parser.add_argument("--descend-clearance", type=float, default=None, metavar="M",
                        help="the planner's opt-in height above the surface above which the tip may not move down "
                             "[m], for every strategy that plans (default: off)")
    parser.add_argument("--payload", default=None, metavar="JSON",
                        help="the payload state of the kept objective, for every strategy that plans: a JSON file "
                             "with the PayloadOptions fields or transfer.json's 'payload' (e.g. "
                             "docs/results/transfer/transfer.json: kept fill with the curl term; default: the "
                             "force model's default payload)")
    parser.add_argument("--force-model", choices=FORCE_MODELS, default="fee",
                        help="the force model ours calibrates and plans with (wheelloader.estimator.FORCE_MODELS; "
                             "fee-learned: the learned correction on fee-payload-depth; default fee)")
    parser.add_argument("--compiled", action="store_true",
                        help="the planner's IPOPT derivatives as C, compiled once per machine and NLP (minutes of "
                             "CPU and about 1 GB each the first time, the same plans); later runs without the flag "
                             "use those libraries too")
    add_ray_arguments(parser)
    parser.add_argument("--report", action="store_true",
                        help="only rewrite the Markdown and the figure from OUT/plant_adaptation.json")
    parser.add_argument("--quick", action="store_true",
                        help="smoke run: gravel, 1 seed, 1 cycle, fixed and ours, MPM dx 6 cm (DEM: the CI "
                             "scenario's coarse spheres)")
    args = parser.parse_args(argv)
    if args.quick:
        args.soils, args.seeds, args.cycles, args.strategies, args.resolution = (["gravel"], 1, 1,
                                                                                  ["fixed", "ours"], 0.06)
    for name in ("rl_path", "rl_closed"):
        if name in args.strategies and not args.rl_policy:
            parser.error(f"--strategies {name} needs --rl-policy ZIP (a policy trained by train/ppo.py)")
    if args.seeds < 1 or args.cycles < 1:
        parser.error("--seeds and --cycles must be >= 1")
    out = Path(args.out)
    if args.report:
        result = json.loads((out / "plant_adaptation.json").read_text())
    else:
        out.mkdir(parents=True, exist_ok=True)
        result = run(args)
        result["summary"] = summarise(result["rows"])
        (out / "plant_adaptation.json").write_text(json.dumps(result, indent=1, default=str))
    text = markdown(result, cycles_dir(args))  # reads every saved cycle: once
    (out / "plant_adaptation.md").write_text(text)
    plot(result, out / "plant_adaptation.png")
    print(text)
    return 0


def plot(result: dict[str, Any], target: Path) -> None:
    """Energy per m³ and fill per cycle and strategy (the plant's own measurements)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for name in dict.fromkeys(r["strategy"] for r in rows):
        cycles = sorted({r["cycle"] for r in rows if r["strategy"] == name})
        sel = {k: [r for r in rows if r["strategy"] == name and r["cycle"] == k] for k in cycles}
        # a cycle that loaded nothing in every loop (a policy's path that never entered the carved pile) has none
        energy = [sum(r["energy_J"] for r in v) / filled / 1e3 if (filled := sum(r["fill_m3"] for r in v)) > 0
                  else math.nan for v in sel.values()]
        fill = [statistics.fmean(r["fill_fraction"] for r in v) * 100 for v in sel.values()]
        err = [statistics.median(r["prediction_rmse_percent"] for r in v) for v in sel.values()]
        axes[0].plot(cycles, energy, "o-", label=name)
        axes[1].plot(cycles, fill, "o-", label=name)
        axes[2].plot(cycles, err, "o-", label=name)
    axes[0].set(xlabel="cycle", ylabel="energy per m³ [kJ/m³]", title="energy per m³ (plant-measured)")
    axes[1].set(xlabel="cycle", ylabel="fill [% of 0.2 m³]", title="fill (plant-measured)")
    axes[2].set(xlabel="cycle", ylabel="F_R RMSE [%]", title="prediction of the cycle (params planned with)")
    for ax in axes:
        ax.set_xticks(sorted({r["cycle"] for r in rows}))
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Adaptation loop in the {result['plant']} plant ({', '.join(result['settings']['soils'])})",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(target, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
