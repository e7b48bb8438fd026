"""The fixed Bezier path dug on the very piles a strategy's plant loop dug: a paired comparison.

In ``benchmarks/adaptation.py --plant mpm`` every strategy carves its own pile cycle after cycle, so from
cycle 2 on the fixed path and a planned path dig different piles. This benchmark takes a run's saved cycles
and, for every cycle of the chosen strategies (default ``ours``), digs the fixed path (the default Bezier path
placed on that cycle's start pile as the loop's ``fixed`` strategy places it,
:func:`wheelloader.planner.bezier_on_face`) in the same plant, soil and seed. Each pair then differs only in
the path: energy (work of the plant's bucket force along the path, :func:`wheelloader.references.metrics.cycle_work`)
and fill (the plant's soil inside the bucket at the end) are measured the same way for both. The cycles it
digs are saved beside the run's (``fixed_on_STRATEGY/cycleK/cycle1.csv.xz`` in each loop's folder of
``--cycles-dir``, default ``OUT/cycles``); a second invocation reads them instead of digging again (one dug
along another path is refused unless ``--force``).

Usage::

    python benchmarks/plant_paired.py --cycles data/results/adaptation_mpm_end55/cycles \\
        --out docs/results/paired_mpm_end55 --cycles-dir data/results/paired_mpm_end55/cycles --ray local --ray-cpus 2
    python benchmarks/plant_paired.py --plant fee-env --cycles RUN/cycles --out /tmp/paired   # FEE env plant
    python benchmarks/plant_paired.py --report --cycles RUN/cycles --out docs/results/paired_mpm_end55  # table only
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

from wheelloader.provenance import commit_label, load_label, machine_info
from wheelloader.ray_mode import add_ray_arguments
from wheelloader.references import make_plant
from wheelloader.saved_loops import saved_loops


def dig_fixed_on_piles(plant: Any, files: list[str], soil: str, seed: int, folder: str,
                       force: bool = False) -> list[dict[str, Any]]:
    """For each saved cycle (a CSV of the loop), the fixed path on its start pile: one row per cycle with both
    paths' plant-measured energy and fill. Each fixed-path cycle is a one-cycle plant loop of the fixed strategy
    on that pile (:func:`wheelloader.loop.run_loop`: the same placement, digest, saved cycle and
    measurement as the run's), saved under ``folder/cycleK`` and read back when present; one saved for another
    path is an error unless ``force``, which digs it again."""
    from wheelloader.adaptation import NOMINAL_SOIL, FixedBezier
    from wheelloader.estimator import CycleLog, WheelloaderError, preset
    from wheelloader.estimator.cyclelog import log_stem
    from wheelloader.loop import run_loop
    from wheelloader.references.metrics import cycle_work
    from wheelloader.saved_loops import load_saved_cycle

    settings = getattr(plant, "settings", None)
    expected = settings.to_dict() if settings is not None else None
    rows = []
    for csv in files:
        log = CycleLog.load(csv)
        if expected is not None and "settings" in log.metadata and log.metadata["settings"] != expected:
            raise ValueError(f"{csv} was dug with plant settings {log.metadata['settings']}, not this plant's "
                             f"{expected} (--resolution?)")
        k = int(log_stem(csv).removeprefix("cycle"))
        cache = Path(folder) / f"cycle{k}"
        try:
            records, _ = run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), log.pile, soil, cycles=1,
                                  seed=seed, cache=cache, stale="redig" if force else "error")
        except WheelloaderError as exc:
            if force or load_saved_cycle(cache, 1) is None:
                raise
            raise WheelloaderError(f"{exc} (the fixed path on {csv}'s pile: pass --force to dig it again)") from None
        fixed = records[0]
        strategy_fill = float(log.fill_volume[-1])
        strategy_energy = cycle_work(log)
        pair = {"cycle": k, "resumed": fixed.end == "resumed from cache",
                "strategy_fill_m3": strategy_fill, "strategy_energy_J": strategy_energy,
                "strategy_energy_per_m3": strategy_energy / strategy_fill if strategy_fill > 0 else float("inf"),
                "fixed_fill_m3": fixed.fill_m3, "fixed_energy_J": fixed.energy_J,
                "fixed_energy_per_m3": fixed.energy_per_m3, "capacity_m3": log.bucket.capacity}
        rows.append(pair)
        print(f"[{soil}, seed {seed}] cycle {k}: strategy {pair['strategy_energy_per_m3'] / 1e3:.1f} "
              f"kJ/m^3 at {strategy_fill:.4f} m^3, fixed {fixed.energy_per_m3 / 1e3:.1f} kJ/m^3 "
              f"at {fixed.fill_m3:.4f} m^3" + (" (resumed)" if pair["resumed"] else ""), flush=True)
    return rows


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per strategy: pooled energy per m^3 (sum of work / sum of fill) of the strategy and of the fixed path on
    the same piles, their ratio, mean fills, and the per-cycle differences."""
    out: dict[str, dict[str, Any]] = {}
    for name in sorted({r["strategy"] for r in rows}):
        sel = [r for r in rows if r["strategy"] == name]
        pooled = {}
        for who in ("strategy", "fixed"):
            pooled[who] = sum(r[f"{who}_energy_J"] for r in sel) / sum(r[f"{who}_fill_m3"] for r in sel)
        fill_diff = [100.0 * (r["strategy_fill_m3"] - r["fixed_fill_m3"]) / r["capacity_m3"] for r in sel]
        ratio = [r["strategy_energy_per_m3"] / r["fixed_energy_per_m3"] for r in sel]
        out[name] = {"cycles": len(sel),
                     "energy_per_m3_kJ": pooled["strategy"] / 1e3, "fixed_energy_per_m3_kJ": pooled["fixed"] / 1e3,
                     "energy_ratio": pooled["strategy"] / pooled["fixed"],
                     "mean_fill_fraction": statistics.fmean(r["strategy_fill_m3"] / r["capacity_m3"] for r in sel),
                     "fixed_mean_fill_fraction": statistics.fmean(r["fixed_fill_m3"] / r["capacity_m3"] for r in sel),
                     "fill_difference_points_median": statistics.median(fill_diff),
                     "fill_difference_points_range": [min(fill_diff), max(fill_diff)],
                     "cycles_with_equal_or_better_fill": sum(1 for d in fill_diff if d >= 0.0),
                     "energy_ratio_per_cycle_median": statistics.median(ratio),
                     "energy_ratio_per_cycle_range": [min(ratio), max(ratio)]}
    return out


def markdown(result: dict[str, Any]) -> str:
    """The paired table and its provenance line."""
    lines = ["| strategy (" + result["plant"] + " plant) | cycles | energy per m³: strategy / fixed on the same piles "
             "| ratio (pooled; per cycle median, range) | mean fill: strategy / fixed | fill difference, points "
             "(median, range) | cycles with equal or better fill |", "|---|---|---|---|---|---|---|"]
    for name, s in result["summary"].items():
        lo, hi = s["energy_ratio_per_cycle_range"]
        dlo, dhi = s["fill_difference_points_range"]
        lines.append(f"| {name} | {s['cycles']} "
                     f"| {s['energy_per_m3_kJ']:.1f} / {s['fixed_energy_per_m3_kJ']:.1f} kJ/m³ "
                     f"| {s['energy_ratio']:.2f} ({s['energy_ratio_per_cycle_median']:.2f}, {lo:.2f}-{hi:.2f}) "
                     f"| {s['mean_fill_fraction']:.1%} / {s['fixed_mean_fill_fraction']:.1%} "
                     f"| {s['fill_difference_points_median']:+.1f} ({dlo:+.1f} to {dhi:+.1f}) "
                     f"| {s['cycles_with_equal_or_better_fill']}/{s['cycles']} |")
    m = result["machine"]
    lines.append("")
    lines.append(f"*`python benchmarks/plant_paired.py --plant {result['plant']} "
                 f"--cycles {result['settings']['cycles']}`"
                 f" at {commit_label(m)}: for every saved cycle of the strategy, the fixed Bezier path placed on that "
                 "cycle's start pile as the loop's fixed strategy places it, dug in the same plant, soil and seed. "
                 "Energy = plant-measured work / plant-measured fill (pooled: sums over the cycles); fill in % of the "
                 f"nominal bucket; {result['wall_s'] / 60:.0f} min, load average at the end {load_label(m)}.*")
    return "\n".join(lines) + "\n"


def run(args: argparse.Namespace) -> dict[str, Any]:
    from wheelloader.sweep import Unit, run_sweep

    if args.cycles is None:
        raise SystemExit("--cycles is needed: the folder of a plant run's saved loops")
    root = Path(args.cycles)
    if not root.is_dir():
        raise SystemExit(f"--cycles {root}: no such folder (a run of benchmarks/adaptation.py --plant ... saves it)")
    from wheelloader.estimator import WheelloaderError

    try:
        loops = saved_loops(root)
    except WheelloaderError as exc:
        raise SystemExit(str(exc)) from None
    found = {k: v for k, v in loops.items() if k[2] in args.strategies}
    if not found:
        raise SystemExit(f"--cycles {root}: no saved loop of {args.strategies}")
    if args.quick:
        found = {k: v[:1] for k, v in list(found.items())[:1]}
    if args.plant == "mpm" and args.taichi_threads is not None:  # Taichi's threads; the lanes (results): --threads
        from wheelloader.references.mpm import taichi_module

        taichi_module(args.taichi_threads)
    plant = (make_plant("mpm", resolution=args.resolution, threads=args.threads) if args.plant == "mpm"
             else make_plant(args.plant))
    started = time.perf_counter()
    saved = Path(args.cycles_dir) if args.cycles_dir is not None else Path(args.out) / "cycles"
    keys = list(found)
    units = []
    for soil, seed, strategy in keys:
        if not seed.startswith("seed") or not seed.removeprefix("seed").isdigit():
            raise SystemExit(f"--cycles {root}: folder {soil}/{seed} is not SOIL/seedN")
        units.append(Unit(dig_fixed_on_piles, {"plant": plant, "files": [str(f) for f in found[(soil, seed, strategy)]],
                                                "soil": soil, "seed": int(seed.removeprefix("seed")),
                                                "force": args.force,
                                                "folder": str(saved / soil / seed / f"fixed_on_{strategy}")},
                          label=f"{soil} | {seed} | fixed on {strategy}'s piles", num_cpus=1))
    print(f"{len(units)} loops' piles, fixed path dug on each ({args.plant} plant, --ray {args.ray})", flush=True)
    values = run_sweep(units, args.ray, ray_cpus=args.ray_cpus, progress=lambda line: print(line, flush=True))
    rows = []
    for (soil, seed, strategy), loop_rows in zip(keys, values.values_or_raise(), strict=True):
        rows += [dict(r, soil=soil, seed=seed, strategy=strategy) for r in loop_rows]
    result = {"benchmark": "plant_paired", "plant": args.plant, "settings": vars(args),
              "machine": machine_info(), "rows": rows, "wall_s": time.perf_counter() - started}
    result["summary"] = summarise(rows)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", default=None,
                        help="a plant run's saved loops (SOIL/seedN/STRATEGY/cycleK.csv.xz); needed unless --report")
    parser.add_argument("--out", default="results/plant_paired", help="output directory")
    parser.add_argument("--cycles-dir", default=None, metavar="DIR",
                        help="folder where the fixed-path cycles dug are saved and read again (default OUT/cycles)")
    parser.add_argument("--plant", choices=("mpm", "fee-env"), default="mpm",
                        help="the plant the run's cycles were dug in (default mpm)")
    parser.add_argument("--resolution", type=float, default=0.02, help="MPM grid spacing [m] (the run's; default 0.02)")
    parser.add_argument("--threads", type=int, default=1,
                        help="MPM lanes/threads (the run's: the plant's settings must match; default 1)")
    parser.add_argument("--taichi-threads", type=int, default=None, metavar="N",
                        help="MPM plant: the CPU threads Taichi runs (default --threads; the lanes, and so the "
                             "results, stay --threads)")
    parser.add_argument("--strategies", nargs="+", default=["ours"], help="whose piles (default ours)")
    parser.add_argument("--quick", action="store_true", help="smoke run: the first cycle of one loop")
    parser.add_argument("--force", action="store_true",
                        help="dig again a saved fixed-path cycle that was dug along another path (default: refuse)")
    parser.add_argument("--report", action="store_true",
                        help="only regenerate plant_paired.md from the plant_paired.json in --out")
    add_ray_arguments(parser)
    args = parser.parse_args(argv)
    out = Path(args.out)
    if args.report:
        saved = out / "plant_paired.json"
        if not saved.is_file():
            raise SystemExit(f"--report: {saved} not found (run without --report first)")
        result = json.loads(saved.read_text())
    else:
        result = run(args)
        out.mkdir(parents=True, exist_ok=True)
        (out / "plant_paired.json").write_text(json.dumps(result, indent=1, default=str))
    text = markdown(result)
    (out / "plant_paired.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
