"""Look-ahead against greedy over 10 cycles in the MPM plant (#33), from ``benchmarks/lookahead_mpm.sh``'s outputs.

Reads each arm's loops (``OUT/ARM/plant_adaptation.json``, else the parts ``OUT/parts/ARM_SOIL_SEED``, a later part's
row of a cycle replacing an earlier one's) and the saved cycles (``CYCLES/ARM/SOIL/seedS/ours/cycleK``), and writes
``OUT/lookahead_mpm.json``, ``OUT/table.md`` and ``OUT/lookahead_mpm.png``. The arms are the same loop (``ours``:
calibrate on the cycle dug, plan the next one with the kept objective) on the same piles and seeds; only the
planner's ``lookahead`` differs. Every figure is the plant's:

* energy per m³ kept: the plant's work along the path plus the lift of what the bucket holds at the end from the
  path's end height to the fixed path's end height (:func:`wheelloader.planner.kept.dump_height`, 1.20 m), over the
  plant's kept fill, pooled over a loop's cycles (:func:`wheelloader.references.metrics.lifted_work`);
* cycles to move ``--volume`` m³ of kept soil (the first cycle at which the kept volume summed from cycle 1 reaches
  it; None, "> cycles dug", where the loop's cycles do not);
* the gain: the look-ahead's energy per m³ kept over greedy's on the same soil and seed, minus 1 (negative: the
  look-ahead spends less), per loop, with its median and its spread (min, max) over the loops;
* between cycles: the loop's calibration and plan wall seconds (as the loop records them, on a shared machine) and
  the IPOPT iterations of the plan (greedy: its solve and re-plans, from the plan's message; the look-ahead: every
  candidate's and every second cycle's plans, from its message), from cycle 2;
* failures: plans that failed the NumPy check (the loop dug the Bezier fallback) and cycles whose raw plant force
  exceeded the loader's limits (:func:`wheelloader.references.metrics.above_loader_limits`).

Only the cycles both arms dug count in a comparison (a run cut short compares its complete pairs of cycles).

Usage::

    python benchmarks/lookahead_mpm_report.py --out docs/results/lookahead_mpm \\
        --cycles data/results/lookahead_mpm/cycles
"""

from __future__ import annotations

import argparse
import json
import math
import re
import statistics
from pathlib import Path
from typing import Any

#: The arms of ``lookahead_mpm.sh``: greedy first (the reference).
ARMS = ("greedy", "lookahead")
#: The issue's target: the look-ahead at least 5 % better than greedy (energy per m³ kept).
GAIN_TARGET = 0.05
#: The issue's target for the median time between cycles [s].
BETWEEN_TARGET_S = 1.0
#: Kept volume to move [m³]: about 8 of the loops' cycles (each keeps about 0.1 m³ of the nominal 0.2 m³).
MOVE_VOLUME = 0.8
#: IPOPT iterations in a greedy plan's message ("IPOPT <status> in N it." or "IPOPT iterate k of N").
PLAN_ITERATIONS = re.compile(r"IPOPT (?:\S+ in (\d+) it\.|iterate \d+ of (\d+))")
#: The look-ahead's choice in its plan's message (planner/lookahead.py).
CHOICE = re.compile(r"look-ahead chose (?P<name>.+?) \((?P<costs>.+?) kJ/m\^3 kept over two cycles; "
                    r"(?P<iterations>\d+) IPOPT it")


def arm_rows(out: Path, arm: str, cycles: Path | None = None) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The arm's rows (the whole run's JSON, else its parts'; then, with ``cycles``, those of its loops that no JSON
    has, from the saved cycles: :func:`saved_rows`) and the settings and machine of the last JSON read."""
    whole = out / arm / "plant_adaptation.json"
    parts = [p for p in out.glob(f"parts/{arm}_*/plant_adaptation.json")  # ARM_SOIL_SEED, not ARM_kept_...
             if re.fullmatch(rf"{re.escape(arm)}_[^_]+_\d+", p.parent.name)]
    paths = [whole] if whole.is_file() else sorted(parts, key=lambda p: p.stat().st_mtime)
    rows: dict[tuple, dict[str, Any]] = {}
    last: dict[str, Any] = {}
    for path in paths:
        last = json.loads(path.read_text())
        for r in last["rows"]:
            rows[(r["soil"], r["seed"], r["cycle"])] = r
    if cycles is not None:
        loops = {(soil, seed) for soil, seed, _ in rows}
        rows.update({(r["soil"], r["seed"], r["cycle"]): r for r in saved_rows(cycles / arm, arm)
                     if (r["soil"], r["seed"]) not in loops})
    if not rows:
        raise SystemExit(f"{out}: no plant_adaptation.json and no saved cycles of the {arm} arm "
                         "(benchmarks/lookahead_mpm.sh)")
    return list(rows.values()), {"settings": last.get("settings", {}), "machine": last.get("machine", {})}


def saved_rows(folder: Path, arm: str) -> list[dict[str, Any]]:
    """Rows of a loop cut short before its invocation wrote its JSON, from its saved cycles: the plant's fill and
    work (:func:`wheelloader.references.metrics.cycle_work`, as the loop measures a plant), the plan's message and
    seconds; no calibration seconds or prediction error (NaN). A look-ahead arm's folder starts as a copy of
    greedy's cycles: its cycles count up to the last one its look-ahead planned ("look-ahead chose" in the
    message; the copies before it were the same paths, or it would have dug them again), not the copies after."""
    from wheelloader.references.metrics import cycle_work
    from wheelloader.saved_loops import load_saved_cycle

    rows = []
    for loop in sorted(folder.glob("*/seed*/ours")):
        soil, seed = loop.parent.parent.name, int(loop.parent.name.removeprefix("seed"))
        found = []
        while (log := load_saved_cycle(loop, len(found) + 1, check=False)) is not None:
            found.append(log)
        plans = [log.metadata.get("plan") or {} for log in found]
        last = len(found) if arm == "greedy" else max(
            (k + 1 for k, plan in enumerate(plans) if "look-ahead chose" in str(plan.get("message", ""))), default=0)
        for k, (log, plan) in enumerate(zip(found[:last], plans, strict=False), start=1):
            rows.append({"soil": soil, "seed": seed, "cycle": k, "fill_m3": float(log.fill_volume[-1]),
                         "energy_J": cycle_work(log), "plan_ok": bool(plan.get("ok", False)),
                         "plan_message": str(plan.get("message", "")), "calibration_s": math.nan,
                         "planning_s": float(plan.get("seconds", math.nan)), "prediction_rmse_percent": math.nan})
    return rows


def plan_iterations(arm: str, message: str) -> float:
    """IPOPT iterations of a cycle's plan from its message (the look-ahead's total where it weighed candidates)."""
    if arm == "lookahead" and (m := CHOICE.search(message)) is not None:
        return float(m.group("iterations"))
    m = PLAN_ITERATIONS.search(message)
    return float(m.group(1) or m.group(2)) if m is not None else math.nan


def predicted_gain(message: str) -> tuple[str, float] | None:
    """The look-ahead's chosen candidate and its predicted two-cycle gain over greedy [%] (None without a choice)."""
    m = CHOICE.search(message)
    if m is None:
        return None
    costs = dict(part.rsplit(" ", 1) for part in m.group("costs").split(", "))
    greedy, best = float(costs.get("greedy", "inf")), float(costs[m.group("name")])
    gain = 100.0 * (1.0 - best / greedy) if math.isfinite(greedy) and math.isfinite(best) else math.nan
    return m.group("name"), gain


def collect(out: Path, cycles: Path, versus: str = "lookahead") -> dict[str, Any]:
    """Per cycle rows of greedy and the look-ahead arm ``versus`` (its folder under OUT and CYCLES; its rows are
    labelled ``"lookahead"``) with the lifted energy and the plant's failures."""
    from wheelloader.planner.kept import dump_height
    from wheelloader.references.metrics import above_loader_limits, lifted_work
    from wheelloader.saved_loops import load_saved_cycle

    z_ref = dump_height()
    rows, runs = [], {}
    for arm, folder in zip(ARMS, ("greedy", versus), strict=True):
        found, runs[arm] = arm_rows(out, folder, cycles)
        for r in found:
            log = load_saved_cycle(cycles / folder / r["soil"] / f"seed{r['seed']}" / "ours", r["cycle"], check=False)
            if log is None:
                raise SystemExit(f"cycle {r['cycle']} of {r['soil']} seed {r['seed']} ({folder}) is not saved under "
                                 f"{cycles / folder}")
            row = {"arm": arm, **{k: r[k] for k in ("soil", "seed", "cycle", "fill_m3", "energy_J", "plan_ok",
                                                     "plan_message", "calibration_s", "planning_s",
                                                     "prediction_rmse_percent")}}
            row.update(above_limits=above_loader_limits(log), capacity_m3=log.bucket.capacity,
                       z_end=float(log.path.z[-1]), lifted_J=lifted_work(r["energy_J"], r["fill_m3"], log, z_ref,
                                                                         r["soil"]),
                       iterations=plan_iterations(arm, r["plan_message"]))
            rows.append(row)
    rows.sort(key=lambda r: (r["soil"], r["seed"], ARMS.index(r["arm"]), r["cycle"]))
    return {"z_ref_m": z_ref, "versus": versus, "runs": runs, "rows": rows}


def loop_figures(rows: list[dict[str, Any]], volume: float = MOVE_VOLUME) -> dict[str, Any]:
    """One loop's figures over ``rows`` (its cycles in order)."""
    fill = sum(r["fill_m3"] for r in rows)
    moved, to_move = 0.0, None
    for r in rows:
        moved += r["fill_m3"]
        if moved >= volume - 1e-12:  # the sum of the kept volumes, to rounding
            to_move = r["cycle"]
            break
    later = [r for r in rows if r["cycle"] >= 2]
    timed = [r for r in later if math.isfinite(r["calibration_s"] + r["planning_s"])]  # not from saved cycles
    med = (lambda key: statistics.median(r[key] for r in timed)) if timed else (lambda key: math.nan)  # noqa: E731
    iterations = [r["iterations"] for r in later if math.isfinite(r["iterations"])]
    choices = [c for r in rows if (c := predicted_gain(r["plan_message"])) is not None]
    gains = [g for _, g in choices if math.isfinite(g)]
    return {"cycles": len(rows), "kJ_per_kept_m3": sum(r["lifted_J"] for r in rows) / fill / 1e3 if fill else math.inf,
            "plant_kJ_per_kept_m3": sum(r["energy_J"] for r in rows) / fill / 1e3 if fill else math.inf,
            "kept_fill": statistics.fmean(r["fill_m3"] / r["capacity_m3"] for r in rows),
            "kept_m3": fill, "cycles_to_move": to_move,
            "failed_plans": sum(not r["plan_ok"] for r in rows),
            "above_limits": sum(bool(r.get("above_limits")) for r in rows),
            "between_total_s_median": statistics.median(r["calibration_s"] + r["planning_s"] for r in timed)
            if timed else math.nan,
            "calibration_s_median": med("calibration_s"), "planning_s_median": med("planning_s"),
            "iterations_median": statistics.median(iterations) if iterations else math.nan,
            "s_per_iteration_median": statistics.median(r["planning_s"] / r["iterations"] for r in later
                                                        if math.isfinite(r["iterations"]) and r["iterations"] > 0)
            if iterations else math.nan,
            "non_greedy_choices": sum(name != "greedy" for name, _ in choices), "choices": len(choices),
            "predicted_gain_percent_median": statistics.median(gains) if gains else math.nan}


def summarise(data: dict[str, Any], volume: float = MOVE_VOLUME) -> dict[str, Any]:
    """Per loop and arm the figures over the cycles both arms dug, the gains and the verdicts."""
    rows = data["rows"]
    loops = sorted({(r["soil"], r["seed"]) for r in rows})
    per_loop: dict[str, Any] = {}
    for soil, seed in loops:
        sel = {arm: {r["cycle"]: r for r in rows if (r["soil"], r["seed"], r["arm"]) == (soil, seed, arm)}
               for arm in ARMS}
        common = sorted(set(sel["greedy"]) & set(sel["lookahead"]))
        if not common or common != list(range(1, len(common) + 1)):
            continue
        figs = {arm: loop_figures([sel[arm][k] for k in common], volume) for arm in ARMS}
        g, la = figs["greedy"], figs["lookahead"]
        moves = (la["cycles_to_move"] - g["cycles_to_move"]
                 if la["cycles_to_move"] is not None and g["cycles_to_move"] is not None else None)
        per_loop[f"{soil} seed {seed}"] = {
            "soil": soil, "seed": seed, "cycles": len(common), **figs,
            "gain_percent": 100.0 * (la["kJ_per_kept_m3"] / g["kJ_per_kept_m3"] - 1.0),
            "kept_fill_points": 100.0 * (la["kept_fill"] - g["kept_fill"]),
            "cycles_to_move_difference": moves,
            "same_paths_from_cycle1": _same_prefix(sel, common)}
    out: dict[str, Any] = {"volume_m3": volume, "loops": per_loop}
    if per_loop:
        gains = [q["gain_percent"] for q in per_loop.values()]
        pooled = {arm: loop_figures([r for r in rows if r["arm"] == arm and f"{r['soil']} seed {r['seed']}" in per_loop
                                     and r["cycle"] <= per_loop[f"{r['soil']} seed {r['seed']}"]["cycles"]], volume)
                  for arm in ARMS}
        between = {arm: [v for r in rows if r["arm"] == arm and r["cycle"] >= 2 and f"{r['soil']} seed {r['seed']}"
                         in per_loop and math.isfinite(v := r["calibration_s"] + r["planning_s"])] for arm in ARMS}
        out.update(gain_percent_median=statistics.median(gains), gain_percent_min=min(gains),
                   gain_percent_max=max(gains),
                   gain_percent_pooled=100.0 * (pooled["lookahead"]["kJ_per_kept_m3"]
                                                / pooled["greedy"]["kJ_per_kept_m3"] - 1.0),
                   pooled={arm: {k: v for k, v in f.items() if k != "cycles_to_move"} for arm, f in pooled.items()},
                   between_s_median={arm: statistics.median(v) if v else math.nan for arm, v in between.items()},
                   verdict_gain=statistics.median(gains) <= -100.0 * GAIN_TARGET)
        out["verdict_between"] = out["between_s_median"]["lookahead"] <= BETWEEN_TARGET_S
    return out


def _same_prefix(sel: dict[str, dict[int, dict[str, Any]]], common: list[int]) -> int:
    """The cycles from the first in which both arms dug the same (fill and energy equal: the same saved cycle)."""
    n = 0
    for k in common:
        a, b = sel["greedy"][k], sel["lookahead"][k]
        if a["fill_m3"] != b["fill_m3"] or a["energy_J"] != b["energy_J"]:
            break
        n += 1
    return n


def _moves(v: int | None) -> str:
    return "> cycles dug" if v is None else str(v)


def markdown(data: dict[str, Any], summary: dict[str, Any], command: str) -> str:
    """The page's generated table."""
    z, vol = data["z_ref_m"], summary["volume_m3"]
    lines = [f"| loop | cycles | arm | energy per m³ kept, lifted to {z:.2f} m | mean kept fill | cycles to move "
             f"{vol:g} m³ kept | failed plans / above the loader's limits | look-ahead chose another plan "
             "(predicted two-cycle gain, median) | between cycles, median (calibration + plan) | IPOPT it. "
             "(median) |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, q in summary["loops"].items():
        for arm in ARMS:
            f = q[arm]
            chose = (f"{f['non_greedy_choices']}/{f['choices']} ({f['predicted_gain_percent_median']:.1f} %)"
                     if arm == "lookahead" and f["choices"] else "–")
            label = arm if arm == "greedy" else data.get("versus", arm)
            lines.append(f"| {name} | {q['cycles']} | {label} | {f['kJ_per_kept_m3']:.1f} kJ/m³ | "
                         f"{f['kept_fill']:.1%} | "
                         f"{_moves(f['cycles_to_move'])} | {f['failed_plans']} / {f['above_limits']} | {chose} | "
                         f"{f['between_total_s_median']:.1f} s ({f['calibration_s_median']:.2f} + "
                         f"{f['planning_s_median']:.1f} s) | {f['iterations_median']:.0f} |")
    if summary["loops"]:
        lines += ["", "| look-ahead against greedy (same soil, seed, piles) | energy per m³ kept | kept fill | cycles "
                  f"to move {vol:g} m³ | cycles alike from cycle 1 |", "|---|---|---|---|---|"]
        for name, q in summary["loops"].items():
            d = q["cycles_to_move_difference"]
            lines.append(f"| {name} | {q['gain_percent']:+.1f} % | {q['kept_fill_points']:+.1f} points | "
                         f"{'–' if d is None else f'{d:+d}'} | {q['same_paths_from_cycle1']} |")
        yes = {True: "yes", False: "**no**"}
        between = summary["between_s_median"]
        lines += ["", "| #33 target (MPM plant) | measured | met |", "|---|---|---|",
                  f"| look-ahead ≥ 5 % less energy per m³ kept than greedy over 10 cycles, same seeds | median "
                  f"{summary['gain_percent_median']:+.1f} % over {len(summary['loops'])} loops (spread "
                  f"{summary['gain_percent_min']:+.1f} to {summary['gain_percent_max']:+.1f} %; pooled "
                  f"{summary['gain_percent_pooled']:+.1f} %) | {yes[summary['verdict_gain']]} |",
                  f"| between cycles ≤ 1 s median, look-ahead included | look-ahead "
                  f"{between['lookahead']:.1f} s, greedy {between['greedy']:.1f} s (wall) | "
                  f"{yes[summary['verdict_between']]} |"]
    run = data["runs"]["lookahead"] if data["runs"]["lookahead"].get("settings") else data["runs"]["greedy"]
    from wheelloader.provenance import commit_label, load_label

    st = run["settings"]
    cut = "" if data["runs"]["lookahead"].get("settings") else (
        " (the look-ahead's loop was cut short before it wrote its JSON: its rows are its saved cycles', without "
        "calibration seconds)")
    lines += ["", f"*`{command}` (MPM dx {st['resolution']} m, {st['threads']} lanes, Taichi threads "
              f"{st.get('taichi_threads') or st['threads']}; held prior, kept objective, descend clearance "
              f"{st.get('descend_clearance')} m; look-ahead arm `{data.get('versus', 'lookahead')}`{cut}) at "
              f"{commit_label(run['machine'])}; load average at the last invocation's end "
              f"{load_label(run['machine'])}. Energy per m³ kept: the plant's work plus "
              f"the lift of its kept load from the path's end to {z:.2f} m, over the plant's kept fill, pooled over "
              "the cycles both arms dug; gain: look-ahead over greedy − 1 (negative: less energy). Between cycles: "
              "the loop's wall seconds from cycle 2 on a shared 2-core machine.*"]
    return "\n".join(lines) + "\n"


def plot(data: dict[str, Any], summary: dict[str, Any], target: Path) -> None:
    """Per loop: energy per m³ kept per cycle and the kept volume summed from cycle 1, greedy against look-ahead."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(summary["loops"])
    fig, axes = plt.subplots(2, max(len(names), 1), figsize=(3.6 * max(len(names), 1), 6), squeeze=False)
    for j, name in enumerate(names):
        q = summary["loops"][name]
        for arm, style in zip(ARMS, ("o-", "s--"), strict=True):
            sel = [r for r in data["rows"] if (r["soil"], r["seed"], r["arm"]) == (q["soil"], q["seed"], arm)
                   and r["cycle"] <= q["cycles"]]
            ks = [r["cycle"] for r in sel]
            axes[0, j].plot(ks, [r["lifted_J"] / r["fill_m3"] / 1e3 if r["fill_m3"] > 0 else math.nan for r in sel],
                            style, label=f"{arm} ({q[arm]['kJ_per_kept_m3']:.1f} kJ/m³)")
            moved, total = [], 0.0
            for r in sel:
                total += r["fill_m3"]
                moved.append(total)
            axes[1, j].plot(ks, moved, style, label=arm)
        axes[1, j].axhline(summary["volume_m3"], color="grey", lw=0.8)
        axes[0, j].set(title=f"{name}: {q['gain_percent']:+.1f} %", xlabel="cycle", ylabel="kJ per m³ kept (lifted)")
        axes[1, j].set(xlabel="cycle", ylabel="kept volume moved [m³]")
        axes[0, j].legend(fontsize=7)
        axes[1, j].legend(fontsize=7)
    fig.suptitle("look-ahead against greedy in the MPM plant (same piles and seeds)", fontsize=10)
    fig.tight_layout()
    fig.savefig(target, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="docs/results/lookahead_mpm", help="lookahead_mpm.sh's OUT (read, written)")
    parser.add_argument("--cycles", default="data/results/lookahead_mpm/cycles", help="lookahead_mpm.sh's CYCLES")
    parser.add_argument("--volume", type=float, default=MOVE_VOLUME, help="kept volume to move [m^3]")
    parser.add_argument("--versus", default="lookahead",
                        help="the look-ahead arm compared with greedy (lookahead or lookahead_kept; outputs named "
                             "with it unless lookahead)")
    parser.add_argument("--command", default="bash benchmarks/lookahead_mpm.sh",
                        help="the run's command, quoted in the table's note")
    args = parser.parse_args(argv)
    if not args.volume > 0:
        parser.error(f"--volume must be positive, got {args.volume}")
    out = Path(args.out)
    data = collect(out, Path(args.cycles), args.versus)
    summary = summarise(data, args.volume)
    tag = "" if args.versus == "lookahead" else f"_{args.versus}"
    (out / f"lookahead_mpm{tag}.json").write_text(json.dumps({**data, "summary": summary}, indent=1, default=str))
    text = markdown(data, summary, args.command)
    (out / f"table{tag}.md").write_text(text)
    plot(data, summary, out / f"lookahead_mpm{tag}.png")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
