"""Next-cycle prediction on a plant's saved loops, replayed: which calibration predicts the next cycle best.

The adaptation loop on a plant (``benchmarks/adaptation.py --plant mpm``) saves every cycle it dug. This
benchmark replays those cycles without digging: for every loop (soil, seed, strategy) and every cycle k >= 2
it calibrates on the cycles before k with each calibration variant (the last ``window`` cycles together, the
force model's failure-angle rule, the opt-in carried-load term, the paper's multi-stage method) and predicts
cycle k on its own path and pile. The error is the loop's: F_R RMSE of the prediction against the plant's
force filtered as in the loop (sigma 0.1 s), in % of the mean |F_R| in soil. Every variant sees the same
cycles, so the table compares calibrations, not the paths they would have planned (those were planned by the
loop's strategy). Also the calibration time per variant (median, this machine), and how much of the next cycle
the prediction's 90 % band covers (the share of its in-soil samples inside the band, pooled per soil; the band
of :func:`wheelloader.estimator.predict`, from the fit's covariance and residual noise model).

Usage::

    python benchmarks/plant_replay.py --cycles data/results/adaptation_mpm/cycles --out docs/results/plant_replay
    python benchmarks/plant_replay.py --quick --out /tmp/replay        # 1 loop, 2 variants
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.provenance import commit_label, load_label, machine_info
from wheelloader.saved_loops import saved_loops

#: name -> (method, window (None: every earlier cycle), failure-angle rule[, opt-in carried-load term])
VARIANTS: dict[str, tuple[Any, ...]] = {
    "ours, last cycle (loop default)": ("default", 1, "min_n_gamma"),
    "ours, last 2 cycles": ("default", 2, "min_n_gamma"),
    "ours, all earlier cycles": ("default", None, "min_n_gamma"),
    "ours + least weight force, last cycle": ("default", 1, "min_weight_force"),
    "ours + least weight force, last 2 cycles": ("default", 2, "min_weight_force"),
    "ours + least weight force, all earlier cycles": ("default", None, "min_weight_force"),
    "ours + least weight force + carried load, last cycle": ("default", 1, "min_weight_force", True),
    "paper multi-stage, last cycle": ("multi-stage", 1, "min_n_gamma"),
    # window 0: cycle k fitted to itself -- not a prediction, the floor no calibration on other cycles can beat
    "floor: cycle k fitted to itself (paper's model)": ("default", 0, "min_n_gamma"),
    "floor: cycle k fitted to itself (least weight force)": ("default", 0, "min_weight_force"),
    "floor: cycle k fitted to itself (least weight force + carried load)": ("default", 0, "min_weight_force", True),
}
#: Level of the prediction band whose coverage of the next cycle is measured.
BAND_LEVEL = 0.9
QUICK = ("ours, last cycle (loop default)", "ours + least weight force, all earlier cycles")


def replay(files: list[Path], variant: str, sigma_s: float) -> list[dict[str, Any]]:
    """Calibrate on the cycles before each k (per the variant) and predict cycle k."""
    from wheelloader.estimator import CalibrationOptions, CycleLog, ModelOptions, calibrate, predict
    from wheelloader.references.filtering import filtered

    method, window, rule, *carried = VARIANTS[variant]
    options = ModelOptions(failure_angle=rule, carried_load=bool(carried and carried[0]))
    logs = [filtered(CycleLog.load(f), sigma_s) for f in files]
    rows = []
    previous = None
    for k in range(2, len(logs) + 1):
        if window == 0:  # the floor: cycle k fitted to itself, cold (no warm start from another cycle)
            start = time.perf_counter()
            result = calibrate(logs[k - 1], options=CalibrationOptions(method=method, model_options=options))
            seconds = time.perf_counter() - start
            rows.append({"variant": variant, "cycle": k, "calibrated_on": 1, "seconds": seconds,
                         "converged": bool(result.success), "rmse_percent": result.quality.percent_r,
                         "band_inside": 0,
                         "band_samples": 0, "floor": True, "params": result.params.to_dict()})
            continue
        earlier = logs[:k - 1] if window is None else logs[max(0, k - 1 - window):k - 1]
        start = time.perf_counter()
        result = calibrate(earlier if len(earlier) > 1 else earlier[0],
                           options=CalibrationOptions(method=method, initial=previous, model_options=options))
        seconds = time.perf_counter() - start
        if result.success:
            previous = result
        params = previous.params if previous is not None else None  # the last converged fit
        # the prediction with its band (from the last converged fit's covariance and residual noise model)
        pred = predict(previous, logs[k - 1], options=options, band=BAND_LEVEL) if previous is not None else None
        quality = pred.quality if pred is not None else None
        inside = samples = 0
        if pred is not None and pred.band is not None:
            in_soil = pred.state.depth > 0.0
            observed = logs[k - 1].resultant
            samples = int(np.count_nonzero(in_soil))
            inside = round(pred.band.coverage(observed, in_soil) * samples)  # a share of samples: an exact count
        rows.append({"variant": variant, "cycle": k, "calibrated_on": len(earlier), "seconds": seconds,
                     "converged": bool(result.success),
                     "rmse_percent": quality.percent_r if quality is not None else math.nan,
                     "band_inside": inside, "band_samples": samples,
                     "params": params.to_dict() if params is not None else None})
    return rows


def _pooled_coverage(rows: Any) -> float:
    """Share of the in-soil samples inside the band, pooled over ``rows`` (NaN without any)."""
    pairs = [(r.get("band_inside", 0), r.get("band_samples", 0)) for r in rows]
    samples = sum(n for _, n in pairs)
    return sum(i for i, _ in pairs) / samples if samples else math.nan


def summarise(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for variant in dict.fromkeys(r["variant"] for r in rows):
        sel = [r for r in rows if r["variant"] == variant]
        per_soil, coverage = {}, {}
        for soil in dict.fromkeys(r["soil"] for r in sel):
            from3 = [r["rmse_percent"] for r in sel if r["soil"] == soil and r["cycle"] >= 3]
            per_soil[soil] = statistics.median(from3) if from3 else math.nan
            coverage[soil] = {"all": _pooled_coverage(r for r in sel if r["soil"] == soil),
                              "from_cycle3": _pooled_coverage(r for r in sel if r["soil"] == soil and r["cycle"] >= 3)}
        by_strategy: dict[str, dict[str, float]] = {}
        for strategy in dict.fromkeys(r.get("strategy", "?") for r in sel):
            for soil in dict.fromkeys(r["soil"] for r in sel):
                from3 = [r["rmse_percent"] for r in sel
                         if r.get("strategy", "?") == strategy and r["soil"] == soil and r["cycle"] >= 3]
                if from3:
                    by_strategy.setdefault(strategy, {})[soil] = statistics.median(from3)
        single = [r["seconds"] for r in sel if r["calibrated_on"] == 1]
        multi = [r["seconds"] for r in sel if r["calibrated_on"] >= 2]
        out[variant] = {
            "median_rmse_percent": statistics.median(r["rmse_percent"] for r in sel),
            "median_rmse_percent_from_cycle3": statistics.median(r["rmse_percent"] for r in sel if r["cycle"] >= 3),
            "median_from_cycle3_per_soil": per_soil,
            "median_from_cycle3_per_strategy": by_strategy,
            "band_coverage_per_soil": coverage,
            "median_seconds_one_cycle": statistics.median(single) if single else math.nan,
            "median_seconds_several": statistics.median(multi) if multi else math.nan,
            "predictions": len(sel)}
    return out


def markdown(result: dict[str, Any]) -> str:
    summary = result["summary"]
    soils = list(dict.fromkeys(r["soil"] for r in result["rows"]))
    lines = ["| calibration (replayed on the plant's saved loops) | next-cycle F_R error, median "
             "(all / from cycle 3) | " + " | ".join(f"{s}, from cycle 3" for s in soils)
             + " | calibration time (1 cycle / several) |",
             "|---|---|" + "---|" * len(soils) + "---|"]
    for variant, m in summary.items():
        several = m["median_seconds_several"]
        lines.append(f"| {variant} | {m['median_rmse_percent']:.1f} / {m['median_rmse_percent_from_cycle3']:.1f} % | "
                     + " | ".join(f"{m['median_from_cycle3_per_soil'].get(s, math.nan):.1f} %" for s in soils)
                     + f" | {m['median_seconds_one_cycle']:.2f} s / "
                     + ("–" if math.isnan(several) else f"{several:.2f} s") + " |")
    level = result["settings"].get("band_level", BAND_LEVEL)
    lines += ["", f"Coverage of the next cycle by the prediction's {level:.0%} band (share of the in-soil samples of "
              "the plant's filtered F_R inside it, pooled over the loops; all cycles / from cycle 3):", "",
              "| calibration | " + " | ".join(soils) + " |", "|---|" + "---|" * len(soils)]
    for variant, m in summary.items():
        if variant.startswith("floor:"):
            continue  # fitted to the cycle itself: no prediction band of an unseen cycle
        cover = m.get("band_coverage_per_soil", {})
        lines.append(f"| {variant} | " + " | ".join(
            f"{cover[s]['all']:.0%} / {cover[s]['from_cycle3']:.0%}" if s in cover else "–" for s in soils) + " |")
    pairs = list(dict.fromkeys((strategy, soil) for m in summary.values()
                               for strategy, per in m.get("median_from_cycle3_per_strategy", {}).items()
                               for soil in per))
    if pairs:
        lines += ["", "Split by the loops the cycles come from (the strategy that dug them: soil), from cycle 3, "
                  "median:", "",
                  "| calibration | " + " | ".join(f"{st}: {so}" for st, so in pairs) + " |",
                  "|---|" + "---|" * len(pairs)]
        for variant, m in summary.items():
            per = m.get("median_from_cycle3_per_strategy", {})
            lines.append(f"| {variant} | " + " | ".join(
                f"{per[st][so]:.1f} %" if so in per.get(st, {}) else "–" for st, so in pairs) + " |")
    s = result["settings"]
    n_loops = len({(r["soil"], r["seed"], r["strategy"]) for r in result["rows"]})
    load = load_label(result["machine"])
    lines += ["", f"*`python benchmarks/plant_replay.py --cycles {s['cycles']}` at {commit_label(result['machine'])}: "
              f"{n_loops} saved loops ({', '.join(soils)}; strategies {', '.join(s['strategies'])}), each cycle "
              "k >= 2 predicted from the cycles before it (the 'floor' rows: cycle k fitted to itself, the best the "
              "model form reaches on it, which no prediction from other cycles can beat); "
              f"{result['wall_s'] / 60:.0f} min, load average at the end {load}. Error: F_R RMSE against the "
              f"plant's force filtered (sigma {s['sigma_s']} s), % of the mean |F_R| in soil, as in the loop.*"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cycles", default="data/results/adaptation_mpm/cycles",
                        help="folder of the saved loops (SOIL/seedN/STRATEGY/cycleK.csv.xz)")
    parser.add_argument("--out", default="results/plant_replay", help="output directory")
    parser.add_argument("--strategies", nargs="+", default=["fixed", "ours", "paper"],
                        help="whose saved loops to replay (default: the learning loops' and the fixed path's)")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS), metavar="NAME",
                        help="calibration variants (default all)")
    parser.add_argument("--sigma-s", type=float, default=0.1, help="Gaussian filter of the plant's force [s]")
    parser.add_argument("--quick", action="store_true", help="smoke run: one loop, two variants")
    args = parser.parse_args(argv)
    root = Path(args.cycles)
    if not root.is_dir():
        raise SystemExit(f"--cycles {root}: no such folder (run benchmarks/adaptation.py --plant mpm first)")
    from wheelloader.estimator import WheelloaderError

    try:
        loops = saved_loops(root)
    except WheelloaderError as exc:
        raise SystemExit(str(exc)) from None
    found = {k: v for k, v in loops.items() if k[2] in args.strategies and len(v) >= 2}
    if not found:
        raise SystemExit(f"--cycles {root}: no saved loop of {args.strategies} with 2 or more cycles")
    variants = list(QUICK) if args.quick else args.variants
    if args.quick:
        found = dict(list(found.items())[:1])
    started = time.perf_counter()
    rows: list[dict[str, Any]] = []
    total = len(found) * len(variants)
    for i, ((soil, seed, strategy), files) in enumerate(found.items()):
        for j, variant in enumerate(variants):
            rows += [dict(r, soil=soil, seed=seed, strategy=strategy) for r in replay(files, variant, args.sigma_s)]
            print(f"[{i * len(variants) + j + 1}/{total}] {soil} {seed} {strategy}: {variant}: "
                  + ", ".join(f"c{r['cycle']} {r['rmse_percent']:.1f} %" for r in rows[-(len(files) - 1):]),
                  flush=True)
    result = {"benchmark": "plant_replay", "settings": vars(args) | {"variants": variants, "band_level": BAND_LEVEL},
              "machine": machine_info(), "rows": rows, "wall_s": time.perf_counter() - started}
    result["summary"] = summarise(rows)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "plant_replay.json").write_text(json.dumps(result, indent=1, default=str))
    (out / "plant_replay.md").write_text(markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
