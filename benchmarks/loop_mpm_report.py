"""The #33 acceptance table of the loop judged in the MPM plant, from ``benchmarks/loop_mpm.sh``'s outputs.

Reads the loops' JSON (``OUT/loops/plant_adaptation.json``, else the latest phase's), the paired run's
(``OUT/paired/plant_paired.json``) and the saved cycles (``CYCLES/loops/SOIL/seedN/STRATEGY/cycleK`` and
``CYCLES/paired/SOIL/seedN/fixed_on_ours/cycleK/cycle1``), and writes ``OUT/acceptance.json``,
``OUT/acceptance.md`` and ``OUT/acceptance.png`` (and ``OUT/headline.md``, the README's short paired table).
Every figure is the plant's:

* energy per m³: the plant's work along the path plus the lift of what the bucket holds at the end from the
  path's end height to the fixed path's end height (:func:`wheelloader.planner.kept.dump_height`, 1.20 m;
  density the continuum's), over the plant's fill (pooled: sums over cycles);
* kept fill: the plant's soil inside the bucket at the end of the path, % of the nominal 0.2 m³;
* next-cycle F_R error: the F_R RMSE of the parameters planned with against the plant's filtered force, median
  over cycles >= 3; the floor: the same cycles, each fitted to itself (``calibrate`` with the strategy's model,
  its error on that cycle), the best the FEE can do there;
* failures: plans that failed the NumPy check (the loop then digs the Bezier fallback), cycles that kept less
  than 1 % of the bucket, stalled cycles (a closed-loop cycle the env's stall rule ended), and cycles whose plant
  force exceeded the loader's limits (F_T > 20 kN or F_N > 25 kN in a raw sample: the loader would have stalled);
  a closed-loop policy's cycles also say how they ended (out of the soil, stall, step limit).

Trained policies (``rl_path``: the policy's FEE-env path replayed open loop; ``rl_closed``: the policy acting on the
plant's state every control step, :mod:`wheelloader.references.mpm.closed_loop`): the rows of ``OUT/rl`` and
``OUT/rl_closed`` are the policy trained in the FEE env's default model; ``--policy LABEL DIR CYCLES`` adds another
policy's (``DIR/rl``, ``DIR/rl_closed``, FEE env ``DIR/fee_env_rl``; cycles ``CYCLES/loops``, ``CYCLES/fee_env``),
its rows named ``STRATEGY (LABEL)``. In the gap table a closed-loop row's FEE-env side is its policy's path there
(the policy closed loop in its own env: the same cycle).

Usage::

    python benchmarks/loop_mpm_report.py --out docs/results/loop_mpm --cycles data/results/loop_mpm/cycles
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
from pathlib import Path
from typing import Any

#: Acceptance targets of #33.
ENERGY_GAIN_TARGET = 0.15
ORACLE_RATIO_TARGET = 1.05
ERROR_TARGET = 15.0
FLOOR_MARGIN = 5.0


def _folder(strategy: str) -> str:
    """The saved loop's folder of a row's strategy: ``rl_path`` (whose records said ``rl`` before 0.2.0)."""
    return "rl_path" if strategy == "rl" else strategy


def lifted(energy_j: float, fill_m3: float, log: Any, z_ref: float, soil: str) -> float:
    """The cycle's energy with its load lifted from the path's end to ``z_ref`` [J]
    (:func:`wheelloader.references.metrics.lifted_work`)."""
    from wheelloader.references.metrics import lifted_work

    return lifted_work(energy_j, fill_m3, log, z_ref, soil)


def floor_percent(log: Any, failure_angle: str, force_model: str = "fee", payload: Any = None) -> float:
    """F_R RMSE [%] of the cycle's own fit on it (filtered as the loop filters): the model's floor there.
    ``force_model``, ``payload``: the model the strategy calibrated and predicted with (the loop's
    ``--force-model`` and ``--payload``; a :class:`~wheelloader.estimator.PayloadOptions` or None, the model's
    own)."""
    from wheelloader.estimator import CalibrationOptions, ModelOptions, calibrate, predict
    from wheelloader.references.filtering import filtered

    options = ModelOptions(failure_angle=failure_angle)
    smooth = filtered(log)
    fit = calibrate(smooth, options=CalibrationOptions(model_options=options, force_model=force_model, payload=payload))
    return float(predict(fit.params, smooth, options=options, force_model=fit.force_model,
                         payload=fit.payload).quality.percent_r)


def ours_model(settings: dict[str, Any]) -> tuple[str, Any]:
    """The force model and payload ``ours`` calibrated and predicted with in a ``plant_adaptation.py`` run
    (its ``settings``: ``force_model``, and ``payload``, a JSON file as ``--payload`` reads it; None: the
    model's own)."""
    from wheelloader.estimator import PayloadOptions

    name, source = settings.get("force_model", "fee"), settings.get("payload")
    if name == "fee" or source is None:
        return name, None
    data = json.loads(Path(source).read_text(encoding="utf-8"))
    return name, PayloadOptions.from_dict(data.get("payload", data) if isinstance(data, dict) else data)


#: The folders of loop_mpm.sh's phases under OUT, in the order they run (``rl``: its RL_POLICY loops; ``rl_closed``:
#: the same policy closed loop in the plant).
PHASES = ("phase1", "phase2", "phase3", "phase4", "loops", "rl", "rl_closed")
#: The strategies whose rows come first in the tables, in this order; the others (policies) follow as found.
PLANNED = ("fixed", "ours", "oracle")


def strategies(rows: list[dict[str, Any]]) -> list[str]:
    """The strategies of ``rows``: the planned ones first, then the others in the order they appear."""
    found = list(dict.fromkeys(r["strategy"] for r in rows))
    return [n for n in PLANNED if n in found] + [n for n in found if n not in PLANNED]


def plant_failures(log: Any) -> dict[str, Any]:
    """What the log says beyond the loop's record: whether a raw sample of the plant's force exceeded the loader's
    limits (:func:`wheelloader.references.metrics.above_loader_limits`), and how a closed-loop cycle ended (None for
    a path)."""
    from wheelloader.references.metrics import above_loader_limits

    closed = log.metadata.get("closed_loop") or {}
    return {"above_limits": above_loader_limits(log), "end": closed.get("end")}


def _latest_loops(out: Path) -> dict[str, Any]:
    """The loops' rows of every phase run so far, a later phase's row of a (soil, seed, strategy, cycle) replacing
    an earlier one's (the last oracle is fitted to the most cycles); settings and machine of the last phase."""
    paths = [out / name / "plant_adaptation.json" for name in PHASES]
    found = [json.loads(path.read_text()) for path in paths if path.is_file()]
    if not found:
        raise SystemExit(f"{out}: no plant_adaptation.json of benchmarks/loop_mpm.sh")
    rows: dict[tuple, dict[str, Any]] = {}
    for result in found:
        for r in result["rows"]:
            rows[(r["soil"], r["seed"], r["strategy"], r["cycle"])] = r
    return {**found[-1], "rows": list(rows.values()), "oracle_fits": [r.get("oracle", {}) for r in found]}


def policy_loops(policies: list[tuple[str, Path, Path]]) -> list[tuple[dict[str, Any], Path, str]]:
    """Each ``--policy``'s loop rows (``DIR/rl``, ``DIR/rl_closed`` or its parts ``DIR/rl_closed_*``) with its saved
    cycles' folder and label."""
    found = []
    for label, folder, cycles in policies:
        # a loop run in parts (one invocation per soil, e.g. rl_closed_gravel) counts as the loop
        for path in [folder / "rl" / "plant_adaptation.json", *sorted(folder.glob("rl_closed*/plant_adaptation.json"))]:
            if path.is_file():
                found += [(r, cycles / "loops", label) for r in json.loads(path.read_text())["rows"]]
    unique = {(label, r["soil"], r["seed"], r["strategy"], r["cycle"]): (r, c, label) for r, c, label in found}
    return list(unique.values())


def collect(out: Path, cycles: Path, policies: list[tuple[str, Path, Path]] | None = None) -> dict[str, Any]:
    """Per cycle rows of every strategy's loop and of the fixed path on ours' piles, with the lifted energy; the
    rows of other ``policies`` (label, results folder, cycles folder) named ``STRATEGY (LABEL)``."""
    from wheelloader.planner.kept import dump_height
    from wheelloader.saved_loops import load_saved_cycle

    z_ref = dump_height()
    loops = _latest_loops(out)
    failure_angle = loops["settings"].get("failure_angle", "min_n_gamma")
    model, payload = ours_model(loops["settings"])
    rows = []
    sources = [(r, cycles / "loops", None) for r in loops["rows"]] + policy_loops(policies or [])
    for r, saved, label in sources:
        r = {**r, "strategy": _folder(r["strategy"])}
        # the plant's own cycles: a closed-loop bucket scraping the bed below the ground has F_N < 0 in most samples
        log = load_saved_cycle(saved / r["soil"] / f"seed{r['seed']}" / r["strategy"], r["cycle"], check=False)
        if log is None:
            raise SystemExit(f"cycle {r['cycle']} of {r['soil']} seed {r['seed']} {r['strategy']} is not saved "
                             f"under {saved}")
        row = {k: r[k] for k in ("soil", "seed", "strategy", "cycle", "fill_m3", "energy_J", "plan_ok", "stalled",
                                 "prediction_rmse_percent", "calibration_s", "planning_s")}
        row.update(plant_failures(log))
        row["stalled"] = bool(row["stalled"]) or row["end"] == "stall"
        if label is not None:
            row["strategy"] = f"{r['strategy']} ({label})"
        row["lifted_J"] = lifted(r["energy_J"], r["fill_m3"], log, z_ref, r["soil"])
        row["z_end"] = float(log.path.z[-1])
        row["capacity_m3"] = log.bucket.capacity
        if r["strategy"] in ("ours", "oracle") and r["cycle"] >= 3:
            # the oracle plans with the FEE; ours with the run's --force-model
            row["floor_percent"] = (floor_percent(log, failure_angle, model, payload) if r["strategy"] == "ours"
                                    else floor_percent(log, failure_angle))
        rows.append(row)
    paired_json = out / "paired" / "plant_paired.json"
    paired = []
    if paired_json.is_file():
        for p in json.loads(paired_json.read_text())["rows"]:
            if p["strategy"] != "ours":
                continue
            seed = int(str(p["seed"]).removeprefix("seed"))
            folder = cycles / "paired" / p["soil"] / f"seed{seed}" / "fixed_on_ours" / f"cycle{p['cycle']}"
            log = load_saved_cycle(folder, 1)
            if log is None:
                raise SystemExit(f"the fixed path on ours' pile {p['soil']} seed {seed} cycle {p['cycle']}: "
                                 f"not saved under {folder}")
            paired.append({"soil": p["soil"], "seed": seed, "cycle": p["cycle"], "fill_m3": p["fixed_fill_m3"],
                           "energy_J": p["fixed_energy_J"], "z_end": float(log.path.z[-1]),
                           "lifted_J": lifted(p["fixed_energy_J"], p["fixed_fill_m3"], log, z_ref, p["soil"]),
                           "capacity_m3": p["capacity_m3"]})
    return {"z_ref_m": z_ref, "settings": loops["settings"], "machine": loops["machine"], "rows": rows,
            "fixed_on_ours": paired}


def pooled(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Energy per m³ (plant's, and with the lift), mean kept fill, mean end height over ``rows``."""
    fill = sum(r["fill_m3"] for r in rows)
    return {"cycles": len(rows), "energy_per_m3_kJ": sum(r["energy_J"] for r in rows) / fill / 1e3,
            "lifted_energy_per_m3_kJ": sum(r["lifted_J"] for r in rows) / fill / 1e3,
            "kept_fill": statistics.fmean(r["fill_m3"] / r["capacity_m3"] for r in rows),
            "end_height_m": statistics.fmean(r["z_end"] for r in rows)}


def summarise(data: dict[str, Any]) -> dict[str, Any]:
    """The acceptance figures: the loops, the paired comparison (also per soil and seed) and the verdicts."""
    rows, paired = data["rows"], data["fixed_on_ours"]
    loops: dict[str, Any] = {}
    for name in strategies(rows):
        sel = [r for r in rows if r["strategy"] == name]
        s = pooled(sel)
        from3 = [r["prediction_rmse_percent"] for r in sel if r["cycle"] >= 3]
        floors = [r["floor_percent"] for r in sel if "floor_percent" in r]
        between = [r["calibration_s"] + r["planning_s"] for r in sel if r["cycle"] >= 2]  # none in a 1-cycle run
        s.update(error_from_cycle3_percent=statistics.median(from3) if from3 else math.nan,
                 floor_percent=statistics.median(floors) if floors else math.nan,
                 failed_plans=sum(1 for r in sel if not r["plan_ok"]) if name in ("ours", "oracle") else 0,
                 stalled=sum(1 for r in sel if r["stalled"]),
                 empty=sum(1 for r in sel if r["fill_m3"] < 0.01 * r["capacity_m3"]),
                 above_limits=sum(1 for r in sel if r.get("above_limits")),
                 ends={e: sum(1 for r in sel if r.get("end") == e) for e in ("exit", "stall", "step limit")
                       if any(r.get("end") == e for r in sel)},
                 between_cycles_s_median=statistics.median(between) if between else math.nan)
        loops[name] = s
    out: dict[str, Any] = {"loops": loops}
    ours = {(r["soil"], r["seed"], r["cycle"]): r for r in rows if r["strategy"] == "ours"}
    pairs = [(ours[key], p) for p in paired if (key := (p["soil"], p["seed"], p["cycle"])) in ours]
    if pairs:
        a, b = pooled([o for o, _ in pairs]), pooled([f for _, f in pairs])
        per_loop = {}
        for soil, seed in sorted({(o["soil"], o["seed"]) for o, _ in pairs}):
            sel = [(o, f) for o, f in pairs if (o["soil"], o["seed"]) == (soil, seed)]
            x, y = pooled([o for o, _ in sel]), pooled([f for _, f in sel])
            per_loop[f"{soil} seed {seed}"] = {"ratio": x["lifted_energy_per_m3_kJ"] / y["lifted_energy_per_m3_kJ"],
                                               "kept_fill": x["kept_fill"], "fixed_kept_fill": y["kept_fill"],
                                               "cycles": len(sel)}
        out["paired"] = {"ours": a, "fixed": b, "ratio": a["lifted_energy_per_m3_kJ"] / b["lifted_energy_per_m3_kJ"],
                         "cycles_kept_ge_fixed": sum(1 for o, f in pairs if o["fill_m3"] >= f["fill_m3"]),
                         "per_loop": per_loop}
        out["verdict_paired"] = (out["paired"]["ratio"] <= 1.0 - ENERGY_GAIN_TARGET
                                 and a["kept_fill"] >= b["kept_fill"])
    if "ours" in loops and "fixed" in loops:
        ratio = loops["ours"]["lifted_energy_per_m3_kJ"] / loops["fixed"]["lifted_energy_per_m3_kJ"]
        out["loop_vs_fixed"] = {"ratio": ratio, "verdict": ratio <= 1.0 - ENERGY_GAIN_TARGET
                                and loops["ours"]["kept_fill"] >= loops["fixed"]["kept_fill"]}
    if "ours" in loops and "oracle" in loops:
        ratio = loops["ours"]["lifted_energy_per_m3_kJ"] / loops["oracle"]["lifted_energy_per_m3_kJ"]
        out["vs_oracle"] = {"ratio": ratio, "kept_fill_difference_points":
                            100 * (loops["ours"]["kept_fill"] - loops["oracle"]["kept_fill"]),
                            "verdict": ratio <= ORACLE_RATIO_TARGET}
    if "ours" in loops and math.isfinite(loops["ours"]["error_from_cycle3_percent"]):
        e, f = loops["ours"]["error_from_cycle3_percent"], loops["ours"]["floor_percent"]
        out["error"] = {"verdict_target": e <= ERROR_TARGET, "verdict_floor": e <= f + FLOOR_MARGIN}
    return out


def fee_rows(fee_outs: list[Path], fee_cycles: Path, z_ref: float, label: str | None = None) -> list[dict[str, Any]]:
    """The same loops in the FEE env plant (``plant_adaptation.py --plant fee-env``, same settings): per cycle the
    kept soil by the payload model (``DEFAULT_PAYLOAD``'s kept fill of the env's carved fill: the model world's
    own kept soil) and the env's work with that load lifted from the path's end to ``z_ref``. A policy's path
    (``rl_path``) stands for it closed loop too (``rl_closed``: in its own env the policy takes that path);
    ``label``: another policy's, its rows named ``STRATEGY (LABEL)``."""
    from wheelloader.estimator import preset
    from wheelloader.estimator.force_model import GRAVITY
    from wheelloader.estimator.force_models import DEFAULT_PAYLOAD
    from wheelloader.estimator.payload import kept_volume
    from wheelloader.saved_loops import load_saved_cycle

    found = [{**r, "strategy": _folder(r["strategy"])} for out in fee_outs
             for r in json.loads((out / "plant_adaptation.json").read_text())["rows"]]
    rows = []
    for r in found:
        log = load_saved_cycle(fee_cycles / r["soil"] / f"seed{r['seed']}" / r["strategy"], r["cycle"])
        if log is None:
            raise SystemExit(f"--fee: cycle {r['cycle']} of {r['soil']} seed {r['seed']} {r['strategy']} is not saved")
        kept = float(kept_volume(r["fill_m3"], log.bucket.capacity, DEFAULT_PAYLOAD))
        z_end = float(log.path.z[-1])
        row = {"soil": r["soil"], "seed": r["seed"], "strategy": r["strategy"], "cycle": r["cycle"],
               "fill_m3": kept, "carved_m3": r["fill_m3"], "energy_J": r["energy_J"], "z_end": z_end,
               "lifted_J": r["energy_J"] + preset(r["soil"]).gamma * GRAVITY * kept * (z_ref - z_end),
               "capacity_m3": log.bucket.capacity}
        names = [r["strategy"]] + (["rl_closed"] if r["strategy"] == "rl_path" else [])
        rows += [{**row, "strategy": name if label is None else f"{name} ({label})"} for name in names]
    return rows


def gap_table(mpm: list[dict[str, Any]], fee: list[dict[str, Any]]) -> dict[str, Any]:
    """Per strategy, over the (soil, seed) loops run in both plants: the FEE env's figure beside the MPM plant's."""
    out = {}
    for name in strategies(mpm):
        keys = ({(r["soil"], r["seed"]) for r in mpm if r["strategy"] == name}
                & {(r["soil"], r["seed"]) for r in fee if r["strategy"] == name})
        if not keys:
            continue
        a = pooled([r for r in fee if r["strategy"] == name and (r["soil"], r["seed"]) in keys])
        b = pooled([r for r in mpm if r["strategy"] == name and (r["soil"], r["seed"]) in keys])
        out[name] = {"loops": sorted(f"{soil} seed {seed}" for soil, seed in keys), "fee": a, "mpm": b,
                     "energy_gap": b["lifted_energy_per_m3_kJ"] / a["lifted_energy_per_m3_kJ"],
                     "kept_gap_points": 100 * (b["kept_fill"] - a["kept_fill"])}
    return out


def markdown(data: dict[str, Any], summary: dict[str, Any]) -> str:
    """The page's generated tables."""
    z = data["z_ref_m"]
    lines = [f"| strategy (MPM loop) | cycles | energy per m³, load lifted to {z:.2f} m | plant's energy per m³ | "
             "mean end height | mean kept fill | next-cycle F_R error from cycle 3 (median) | its floor (median) "
             "| failed plans / empty cycles / stalls / above the loader's limits | between cycles (median) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in summary["loops"].items():
        err = "–" if math.isnan(s["error_from_cycle3_percent"]) else f"{s['error_from_cycle3_percent']:.1f} %"
        flo = "–" if math.isnan(s["floor_percent"]) else f"{s['floor_percent']:.1f} %"
        lines.append(f"| {name} | {s['cycles']} | {s['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | "
                     f"{s['energy_per_m3_kJ']:.1f} kJ/m³ | {s['end_height_m']:.2f} m | {s['kept_fill']:.1%} | {err} | "
                     f"{flo} | {s['failed_plans']} / {s['empty']} / {s['stalled']} / {s['above_limits']} | "
                     f"{s['between_cycles_s_median']:.1f} s |")
    closed = {name: s["ends"] for name, s in summary["loops"].items() if s.get("ends")}
    if closed:
        lines += ["", "| closed loop in the plant | cycles out of the soil | ended by a stall | at the step limit |",
                  "|---|---|---|---|"]
        lines += [f"| {name} | {e.get('exit', 0)} | {e.get('stall', 0)} | {e.get('step limit', 0)} |"
                  for name, e in closed.items()]
    if "paired" in summary:
        p = summary["paired"]
        lines += ["", f"| paired (same piles, only the path differs) | cycles | energy per m³, lifted to {z:.2f} m | "
                  "ratio ours / fixed | mean kept fill | cycles ours keeps ≥ fixed |", "|---|---|---|---|---|---|",
                  f"| ours vs fixed, all | {p['ours']['cycles']} | {p['ours']['lifted_energy_per_m3_kJ']:.1f} / "
                  f"{p['fixed']['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | {p['ratio']:.3f} | "
                  f"{p['ours']['kept_fill']:.1%} / {p['fixed']['kept_fill']:.1%} | "
                  f"{p['cycles_kept_ge_fixed']}/{p['ours']['cycles']} |"]
        for name, q in p["per_loop"].items():
            lines.append(f"| {name} | {q['cycles']} | – | {q['ratio']:.3f} | {q['kept_fill']:.1%} / "
                         f"{q['fixed_kept_fill']:.1%} | – |")
    if summary.get("gap"):
        lines += ["", "| sim-to-real gap | loops | FEE env: energy per m³ kept (lifted) | FEE env: kept fill | "
                  "MPM: energy per m³ (lifted) | MPM: kept fill | MPM / FEE energy | kept fill, MPM − FEE |",
                  "|---|---|---|---|---|---|---|---|"]
        for name, g in summary["gap"].items():
            lines.append(f"| {name} | {len(g['loops'])} | {g['fee']['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | "
                         f"{g['fee']['kept_fill']:.1%} | {g['mpm']['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | "
                         f"{g['mpm']['kept_fill']:.1%} | {g['energy_gap']:.2f} | {g['kept_gap_points']:+.1f} points |")
    lines += ["", "| #33 acceptance (MPM plant) | measured | met |", "|---|---|---|"]
    yes = {True: "yes", False: "**no**"}
    if "paired" in summary:
        p = summary["paired"]
        lines.append(f"| ours ≥ 15 % less energy per m³ than fixed and kept fill ≥ fixed's, paired | energy "
                     f"{100 * (p['ratio'] - 1):+.1f} % vs fixed; kept {p['ours']['kept_fill']:.1%} vs "
                     f"{p['fixed']['kept_fill']:.1%} | {yes[summary['verdict_paired']]} |")
    if "loop_vs_fixed" in summary:
        v, lo = summary["loop_vs_fixed"], summary["loops"]
        lines.append(f"| the same, in the loop (each on its own piles) | energy {100 * (v['ratio'] - 1):+.1f} % vs "
                     f"fixed; kept {lo['ours']['kept_fill']:.1%} vs {lo['fixed']['kept_fill']:.1%} | "
                     f"{yes[v['verdict']]} |")
    if "vs_oracle" in summary:
        v = summary["vs_oracle"]
        lines.append(f"| ours ≤ 1.05 × the hindsight oracle's energy per m³ | {v['ratio']:.3f} × (kept fill "
                     f"{v['kept_fill_difference_points']:+.1f} points vs the oracle) | {yes[v['verdict']]} |")
    if "error" in summary:
        s = summary["loops"]["ours"]
        model = data["settings"].get("force_model", "fee")
        which = ("FEE; the new model is not in the loop" if model == "fee" else f"ours with `{model}`")
        lines.append(f"| next-cycle F_R error from cycle 3 ≤ 15 % ({which}) | "
                     f"{s['error_from_cycle3_percent']:.1f} % | {yes[summary['error']['verdict_target']]} |")
        lines.append(f"| … ≤ 5 points above the run's floor | floor {s['floor_percent']:.1f} % | "
                     f"{yes[summary['error']['verdict_floor']]} |")
    m, st = data["machine"], data["settings"]
    from wheelloader.provenance import commit_label, load_label

    loops = sorted({(r["soil"], r["seed"], r["strategy"]) for r in data["rows"]})
    dug = ", ".join(f"{soil} seed {seed} {name}" for soil, seed, name in loops)
    lines += ["", f"*`bash benchmarks/loop_mpm.sh` then `python benchmarks/loop_mpm_report.py` (MPM dx "
              f"{st['resolution']} m, {st['threads']} lanes; loops of {st['cycles']} cycles: {dug}; planner "
              f"objective `{st.get('objective', 'fill_energy')}`) at "
              f"{commit_label(m)}; load average at the last loop invocation's end {load_label(m)}. Energy per m³: "
              f"the plant's work plus the lift of the plant's kept load from the path's end to {z:.2f} m (the fixed "
              "path's end), over the plant's kept fill, pooled over cycles; kept fill in % of the nominal 0.2 m³.*"]
    return "\n".join(lines) + "\n"


def beside(summary: dict[str, Any], other: dict[str, Any], label: str) -> str:
    """A table of ours' figures in this run beside another run's (its ``acceptance.json`` summary, e.g. the same
    loop with another ``--force-model``): paired energy and kept fill, the loop's, the next-cycle error and its floor,
    failed plans and the time between cycles; a figure a run lacks is a dash."""
    def fig(s: dict[str, Any], *keys: str, fmt: str = "{:.3f}") -> str:
        for key in keys:
            if not isinstance(s, dict) or key not in s:
                return "–"
            s = s[key]
        return "–" if isinstance(s, float) and math.isnan(s) else fmt.format(s)

    rows = [("paired cycles", ("paired", "ours", "cycles"), "{:d}"),
            ("paired energy per m³, ours / fixed (lifted)", ("paired", "ratio"), "{:.3f}"),
            ("paired kept fill, ours", ("paired", "ours", "kept_fill"), "{:.1%}"),
            ("paired kept fill, fixed", ("paired", "fixed", "kept_fill"), "{:.1%}"),
            ("paired cycles ours keeps ≥ fixed", ("paired", "cycles_kept_ge_fixed"), "{:d}"),
            ("ours' loops: energy per m³ lifted", ("loops", "ours", "lifted_energy_per_m3_kJ"), "{:.1f} kJ/m³"),
            ("ours' loops vs the fixed path's loops", ("loop_vs_fixed", "ratio"), "{:.3f}"),
            ("ours vs the hindsight oracle", ("vs_oracle", "ratio"), "{:.3f}"),
            ("next-cycle F_R error from cycle 3 (median)", ("loops", "ours", "error_from_cycle3_percent"),
             "{:.1f} %"),
            ("its floor (median)", ("loops", "ours", "floor_percent"), "{:.1f} %"),
            ("failed plans", ("loops", "ours", "failed_plans"), "{:d}"),
            ("above the loader's limits", ("loops", "ours", "above_limits"), "{:d}"),
            ("between cycles (median, wall)", ("loops", "ours", "between_cycles_s_median"), "{:.1f} s")]
    lines = [f"| ours | this run | {label} |", "|---|---|---|"]
    lines += [f"| {name} | {fig(summary, *keys, fmt=f)} | {fig(other, *keys, fmt=f)} |" for name, keys, f in rows]
    return "\n".join(lines) + "\n"


def headline(data: dict[str, Any], summary: dict[str, Any]) -> str:
    """The README's short table (#33 item 4): the paired comparison pooled, with its spread over the loops, and
    beside it every other loop of the run on its own piles (the fixed path's, the trained policies'); empty
    without a paired run."""
    if "paired" not in summary:
        return ""
    p, z = summary["paired"], data["z_ref_m"]
    ratios = [q["ratio"] for q in p["per_loop"].values()]
    lines = [f"| MPM plant, 2 soils × seeds × cycles | cycles | energy per m³ kept, lifted to {z:.2f} m | kept fill | "
             "ours / fixed |", "|---|---|---|---|---|",
             f"| **paired**: fixed path on ours' piles | {p['fixed']['cycles']} | "
             f"{p['fixed']['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | {p['fixed']['kept_fill']:.1%} | – |",
             f"| **paired**: ours (calibrate + plan) | {p['ours']['cycles']} | "
             f"{p['ours']['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | {p['ours']['kept_fill']:.1%} | "
             f"**{p['ratio']:.3f}** (per loop {min(ratios):.3f}–{max(ratios):.3f}) |"]
    for name, s in summary["loops"].items():
        if name == "ours":
            continue
        lines.append(f"| {name}, its own loops | {s['cycles']} | {s['lifted_energy_per_m3_kJ']:.1f} kJ/m³ | "
                     f"{s['kept_fill']:.1%} | – |")
    lines += ["", f"*Paired: the same pile, soil and seed, only the path differs; the target is ours ≤ "
              f"{1.0 - ENERGY_GAIN_TARGET:.2f} × fixed at a kept fill ≥ fixed's. Energy: the plant's work plus the "
              f"lift of what it kept to {z:.2f} m, over what it kept. From `python benchmarks/loop_mpm_report.py` "
              "(`acceptance.md` has every row and the verdicts).*"]
    return "\n".join(lines) + "\n"


def plot(data: dict[str, Any], target: Path) -> None:
    """Energy per m³ (lifted) and kept fill per cycle: ours, the fixed path on ours' piles, fixed and oracle loops."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_e, ax_k) = plt.subplots(1, 2, figsize=(11, 4))
    series = {name: [r for r in data["rows"] if r["strategy"] == name] for name in ("fixed", "ours", "oracle")}
    series["fixed on ours' piles"] = data["fixed_on_ours"]
    for name, sel in series.items():
        ks = sorted({r["cycle"] for r in sel})
        if not ks:
            continue
        e = [sum(r["lifted_J"] for r in sel if r["cycle"] == k) / sum(r["fill_m3"] for r in sel if r["cycle"] == k)
             / 1e3 for k in ks]
        f = [100 * statistics.fmean(r["fill_m3"] / r["capacity_m3"] for r in sel if r["cycle"] == k) for k in ks]
        style = "--" if name.startswith("fixed on") else "-"
        ax_e.plot(ks, e, "o" + style, label=name)
        ax_k.plot(ks, f, "o" + style, label=name)
    ax_e.set(xlabel="cycle", ylabel=f"kJ per m³ kept (lifted to {data['z_ref_m']:.2f} m)",
             title="energy per m³ (MPM plant, pooled over soils and seeds)")
    ax_k.set(xlabel="cycle", ylabel="kept fill [% of 0.2 m³]", title="kept fill (plant)")
    ax_e.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(target, dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="docs/results/loop_mpm", help="loop_mpm.sh's OUT (read and written)")
    parser.add_argument("--cycles", default="data/results/loop_mpm/cycles", help="loop_mpm.sh's CYCLES")
    parser.add_argument("--fee", nargs="+", default=None, metavar="OUT",
                        help="the same loops in the FEE env plant (plant_adaptation.py --plant fee-env --out OUT "
                             "--cycles-dir FEE_CYCLES; one or more invocations): the sim-to-real gap table")
    parser.add_argument("--fee-cycles", default=None, metavar="FEE_CYCLES", help="their saved cycles (with --fee)")
    parser.add_argument("--policy", nargs=3, action="append", default=[], metavar=("LABEL", "DIR", "CYCLES"),
                        help="another trained policy's loops: DIR/rl and DIR/rl_closed (plant_adaptation.py --out), "
                             "DIR/fee_env_rl (the FEE env plant), their cycles under CYCLES/loops and "
                             "CYCLES/fee_env; rows named 'STRATEGY (LABEL)' (repeatable)")
    parser.add_argument("--beside", nargs=2, default=None, metavar=("LABEL", "DIR"),
                        help="a table of ours' figures beside another run's (DIR/acceptance.json, written by this "
                             "script), e.g. the FEE's run beside the learned model's")
    parser.add_argument("--write", default=None, metavar="DIR",
                        help="write acceptance.json/.md/.png here (default OUT)")
    args = parser.parse_args(argv)
    out, cycles = Path(args.out), Path(args.cycles)
    policies = [(label, Path(folder), Path(saved)) for label, folder, saved in args.policy]
    data = collect(out, cycles, policies)
    if args.fee is not None:
        if args.fee_cycles is None:
            parser.error("--fee needs --fee-cycles")
        data["fee_rows"] = fee_rows([Path(f) for f in args.fee], Path(args.fee_cycles), data["z_ref_m"])
        for label, folder, saved in policies:
            if (folder / "fee_env_rl" / "plant_adaptation.json").is_file():
                data["fee_rows"] += fee_rows([folder / "fee_env_rl"], saved / "fee_env", data["z_ref_m"], label)
    summary = summarise(data)
    if args.fee is not None:
        summary["gap"] = gap_table(data["rows"], data["fee_rows"])
    target = Path(args.write) if args.write else out
    target.mkdir(parents=True, exist_ok=True)
    (target / "acceptance.json").write_text(json.dumps({**data, "summary": summary}, indent=1, default=str))
    text = markdown(data, summary)
    if args.beside is not None:
        label, folder = args.beside
        other = json.loads((Path(folder) / "acceptance.json").read_text())["summary"]
        text += "\n" + beside(summary, other, label)
    (target / "acceptance.md").write_text(text)
    short = headline(data, summary)
    if short:
        (target / "headline.md").write_text(short)
    plot(data, target / "acceptance.png")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
