"""One planned cycle in the continuum, per planner variant: what each opt-in piece of physics does to a plan.

On the fresh pile, with the loop's nominal parameters (no calibration), plan the first cycle with each
variant of the planner, dig it in the MPM plant (gravel by default), and measure energy (plant work),
fill (soil in the bucket's outline) and the peak force, beside the fixed Bezier path dug the same way.
The variants switch on, one after the other: the least-weight-force failure angle
(``PlannerOptions.failure_angle``), the heel clearance (``heel_clearance``), the curled end
(``end_blade_angle``) and the cutting cone (``cut_angle``). Also what the model predicted (its fill is the
soil carved; the plant counts the soil kept in the bucket's outline).

Each variant is one unit of :mod:`wheelloader.sweep` (Ray tasks when Ray is installed). Every dug cycle is
saved (xz-compressed) under ``--cycles-dir`` (default ``OUT/cycles/``) with the digest of its path and read
again when the plan is the same.

Usage::

    python benchmarks/plant_first_cycle.py --out docs/results/plant_first_cycle \\
        --cycles-dir data/results/plant_first_cycle/cycles
    python benchmarks/plant_first_cycle.py --quick --out /tmp/first_cycle      # 3 variants at 8 cm
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

from wheelloader.provenance import commit_label, load_label, machine_info
from wheelloader.ray_mode import add_ray_arguments

#: The variants: name -> PlannerOptions keywords (angles in degrees here); None is the fixed Bezier path.
VARIANTS: dict[str, dict[str, Any] | None] = {
    "fixed Bezier path": None,
    "plan, paper model": {},
    "plan, least-weight-force model": {"failure_angle": "min_weight_force"},
    "+ heel clearance 0 m": {"failure_angle": "min_weight_force", "heel_clearance": 0.0},
    "+ heel clearance, end curled 45°": {"failure_angle": "min_weight_force", "heel_clearance": 0.0,
                                         "end_blade_angle": 45.0},
    "+ heel clearance, end curled, cutting cone 55°": {"failure_angle": "min_weight_force", "heel_clearance": 0.0,
                                                       "end_blade_angle": 45.0, "cut_angle": 55.0},
    "paper model + heel clearance, end curled": {"heel_clearance": 0.0, "end_blade_angle": 45.0},
    "+ heel clearance, end curled 45° in a curl-out (last 8 intervals)": {
        "failure_angle": "min_weight_force", "heel_clearance": 0.0, "end_blade_angle": 45.0, "curl_out_intervals": 8},
    "paper model + heel clearance, end curled in a curl-out": {"heel_clearance": 0.0, "end_blade_angle": 45.0,
                                                               "curl_out_intervals": 8},
    # the plant's bucket keeps at most its struck capacity (0.135 of the nominal 0.2 m^3): plan 95 % of that
    "+ heel clearance, curl-out, planned fill <= 64 %": {
        "failure_angle": "min_weight_force", "heel_clearance": 0.0, "end_blade_angle": 45.0, "curl_out_intervals": 8,
        "fill_limit": 0.64},
    "paper model + heel clearance, curl-out, planned fill <= 64 %": {
        "heel_clearance": 0.0, "end_blade_angle": 45.0, "curl_out_intervals": 8, "fill_limit": 0.64},
}
QUICK = ("fixed Bezier path", "+ heel clearance, end curled 45°")


def dig_variant(name: str, settings: dict[str, Any] | None, soil: str, resolution: float, seed: int,
                cache: str) -> dict[str, Any]:
    """Plan (or take the Bezier path), dig in the MPM plant (or read the saved cycle), measure."""
    import numpy as np

    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, LOOP_EXIT_MIN_FILL, NOMINAL_SOIL
    from wheelloader.estimator import CycleLog, Pile, preset
    from wheelloader.estimator.cyclelog import find_cycle_log
    from wheelloader.planner import PlannerOptions, bezier_on_face, plan_next_cycle, verify_plan
    from wheelloader.references import make_plant
    from wheelloader.references.metrics import cycle_work
    from wheelloader.saved_loops import path_digest

    pile = Pile.trapezoid()
    nominal = preset(NOMINAL_SOIL)
    started = time.perf_counter()
    if settings is None:
        path, ok, message, predicted = bezier_on_face(pile, exit_min_fill=LOOP_EXIT_MIN_FILL), True, "Bezier", None
    else:
        kw = {k: (math.radians(v) if k in ("cut_angle", "end_blade_angle") else v) for k, v in settings.items()}
        options = PlannerOptions(max_iter=BETWEEN_CYCLES_MAX_ITER, **kw)
        outcome = plan_next_cycle(nominal, pile, options=options, replan_within_iterations=BETWEEN_CYCLES_MAX_ITER,
                                  exit_min_fill=LOOP_EXIT_MIN_FILL)
        if outcome.path is None:
            return {"variant": name, "settings": settings, "plan_ok": False, "message": outcome.message}
        path, ok, message = outcome.path, outcome.success, outcome.message
        check = verify_plan(path, nominal, pile, options=options, exit_min_fill=LOOP_EXIT_MIN_FILL)
        predicted = {"fill_m3": check.fill, "energy_J": check.energy}
    planning_s = time.perf_counter() - started
    folder = Path(cache)
    folder.mkdir(parents=True, exist_ok=True)
    digest = path_digest(path)
    csv = find_cycle_log(folder, digest[:16])
    if csv is not None:
        log, resumed = CycleLog.load(csv), True
    else:
        csv = folder / f"{digest[:16]}.csv.xz"
        log, resumed = make_plant("mpm", resolution=resolution).dig(path, pile, soil, seed=seed), False
        log.save(csv, overwrite=True)
    energy, fill = cycle_work(log), float(log.fill_volume[-1])
    floor = log.bucket.floor_length
    heel = pile.surface_height(path.x - floor * np.cos(path.blade_angle)) - (path.z - floor * np.sin(path.blade_angle))
    return {"variant": name, "settings": settings, "plan_ok": ok, "message": message, "planning_s": planning_s,
            "energy_J": energy, "fill_m3": fill, "energy_per_m3_kJ": energy / fill / 1e3 if fill > 0 else math.inf,
            "peak_F_R_N": float(np.max(log.resultant)), "max_heel_depth_m": float(np.max(heel)),
            "end_blade_angle_deg": math.degrees(float(path.blade_angle[-1])), "predicted": predicted,
            "resumed": resumed, "cycle": f"{digest[:16]}.csv"}


def markdown(result: dict[str, Any]) -> str:
    rows = result["rows"]
    base = next((r for r in rows if r["settings"] is None and "energy_J" in r), None)
    lines = ["| variant (first cycle, fresh pile, nominal parameters) | plan passes the check | energy per m³ | "
             "fill (plant) | vs the fixed path: energy per m³ / fill | peak F_R | heel depth (max) | end blade "
             "angle | model's fill / energy |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "energy_J" not in r:
            lines.append(f"| {r['variant']} | no plan: {r['message'][:60]} | – | – | – | – | – | – | – |")
            continue
        rel = (f"{r['energy_per_m3_kJ'] / base['energy_per_m3_kJ']:.2f}× / {r['fill_m3'] / base['fill_m3']:.2f}×"
               if base else "–")
        pred = (f"{r['predicted']['fill_m3']:.3f} m³ / {r['predicted']['energy_J'] / 1e3:.1f} kJ"
                if r["predicted"] else "–")
        lines.append(f"| {r['variant']} | {'–' if r['settings'] is None else ('yes' if r['plan_ok'] else 'no')} | "
                     f"{r['energy_per_m3_kJ']:.1f} kJ/m³ | {r['fill_m3']:.3f} m³ | {rel} | "
                     f"{r['peak_F_R_N'] / 1e3:.1f} kN | {r['max_heel_depth_m']:.2f} m | "
                     f"{r['end_blade_angle_deg']:.0f}° | {pred} |")
    s = result["settings"]
    load = load_label(result["machine"])
    lines += ["", f"*`python benchmarks/plant_first_cycle.py` ({s['soil']}, MPM dx {s['resolution']} m, seed "
              f"{s['seed']}) at {commit_label(result['machine'])}; {result['wall_s'] / 60:.0f} min, load average at "
              f"the end {load}. Energy = the plant's work along the path / the plant's fill (soil inside the bucket "
              "outline, at most 0.135 m³); heel depth > 0: the back of the floor below the surface.*"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/plant_first_cycle", help="output directory")
    parser.add_argument("--cycles-dir", default=None, metavar="DIR",
                        help="folder of the dug cycles (the resume cache; default OUT/cycles)")
    parser.add_argument("--soil", default="gravel", help="soil preset of the plant")
    parser.add_argument("--resolution", type=float, default=0.02, help="MPM grid spacing [m]")
    parser.add_argument("--seed", type=int, default=0, help="plant seed")
    parser.add_argument("--quick", action="store_true", help=f"{len(QUICK)} variants at dx 8 cm (smoke run)")
    add_ray_arguments(parser)
    args = parser.parse_args(argv)
    if args.quick:
        args.resolution = 0.08
    names = QUICK if args.quick else tuple(VARIANTS)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from wheelloader.sweep import Unit, run_sweep

    started = time.perf_counter()
    units = [Unit(dig_variant, {"name": n, "settings": VARIANTS[n], "soil": args.soil, "resolution": args.resolution,
                                "seed": args.seed,
                                "cache": args.cycles_dir or str(out / "cycles")}, label=n) for n in names]
    rows = run_sweep(units, args.ray, ray_cpus=args.ray_cpus,
                     progress=lambda line: print(line, flush=True)).values_or_raise()
    result = {"benchmark": "plant_first_cycle", "settings": {k: v for k, v in vars(args).items() if k != "ray"}
              | {"out": str(out), "ray": args.ray}, "machine": machine_info(), "rows": rows,
              "wall_s": time.perf_counter() - started}
    (out / "plant_first_cycle.json").write_text(json.dumps(result, indent=1, default=str))
    (out / "plant_first_cycle.md").write_text(markdown(result))
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
