"""``wheelloader plan``: the next cycle's bucket path for a calibration and a pile.

* ``wheelloader plan params.json [--pile P] [--energy-weight L] [--pareto] -o plan.csv [--plot plan.png]``
  plans a full cycle with the CasADi/IPOPT trajectory optimiser, re-simulates
  the plan with the NumPy force model and checks every constraint, writes the
  path with the predicted forces as CSV (``t, x, z, blade_angle, depth, fill,
  F_T, F_N``; readable by ``wheelloader predict`` as a path) and a JSON summary
  beside it (``plan.summary.json``), and prints timing, fill, energy, energy per
  m^3 and the check result next to the paper's default Bezier path on the same
  face. ``--pareto`` adds a sweep over the energy weight (fill against energy).

As in the cycle-to-cycle loop (:func:`~wheelloader.planner.loop.plan_next_cycle`),
a plan that fails the check is re-planned once with wider margins, and a plan
that passes it is usable even when IPOPT stopped without success (then it is
reported as feasible but not proven optimal). Exit status 0 when the plan
passed the check, 1 when it was written but failed (the summary says why), 2
for bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

import numpy as np

#: Summary file written beside the CSV: ``plan.csv`` -> ``plan.summary.json`` (not ``plan.json``, which
#: would make the CSV look like a cycle log to ``wheelloader predict``).
SUMMARY_SUFFIX = ".summary.json"


def register(subparsers: Any) -> None:
    """Add the ``plan`` subcommand."""
    from wheelloader.estimator.commands import PILE_PRESETS

    p = subparsers.add_parser("plan", help="plan the next cycle's bucket path (fill against energy)",
                              description=__doc__.splitlines()[2].strip("* "))
    p.add_argument("params", help="params.json from 'wheelloader calibrate' (or a bare 8-parameter JSON, "
                                  "or a soil preset name such as gravel)")
    p.add_argument("--pile", help="pile: JSON file with {\"x\": [...], \"z\": [...]} (or a cycle-log sidecar), "
                                  f"or a preset: {', '.join(PILE_PRESETS)}, ideal_slope (default: trapezoid)")
    p.add_argument("--energy-weight", type=float, default=None, metavar="L",
                   help="energy weight lambda per kJ, in bucket-fills (default: the planner's, 0.02)")
    p.add_argument("--pareto", action="store_true", help="also sweep lambda and report fill against energy")
    p.add_argument("--weights", default=None, metavar="L1,L2,...",
                   help="comma-separated lambdas of the --pareto sweep (default: 0,0.005,0.01,0.02,0.05,0.1,0.2)")
    p.add_argument("--rate", type=float, default=60.0, help="sampling rate of the CSV and the check [Hz] "
                                                            "(default: %(default)s)")
    p.add_argument("-o", "--output", default="plan.csv", help="output path CSV (default: %(default)s); "
                                                              f"the summary goes beside it as *{SUMMARY_SUFFIX}")
    p.add_argument("--plot", help="write a figure (PNG): path, predicted forces and limits (+ Pareto front)")
    p.add_argument("--force", "--overwrite", dest="force", action="store_true",
                   help="replace existing output files")
    p.set_defaults(func=run_plan)


def _load_soil(spec: str):
    from wheelloader.estimator.calibration import load_params
    from wheelloader.estimator.errors import ParameterError
    from wheelloader.estimator.soil import PRESET_NAMES

    path = Path(spec)
    if path.exists() or path.suffix.lower() == ".json":
        if not path.exists():
            raise ParameterError(f"params file {spec} not found")
        if path.is_dir():
            raise ParameterError(f"params {spec} is a directory; give a params.json file")
        return load_params(path)
    try:
        return load_params(spec)
    except ParameterError:
        raise ParameterError(f"params {spec!r} is neither a file nor a soil preset "
                             f"({', '.join(PRESET_NAMES)})") from None


def _parse_weights(text: str | None) -> tuple[float, ...]:
    from wheelloader.estimator.errors import ParameterError

    from .pareto import DEFAULT_WEIGHTS

    if text is None:
        return DEFAULT_WEIGHTS
    try:
        weights = tuple(float(w) for w in text.split(",") if w.strip())
    except ValueError:
        raise ParameterError(f"--weights must be comma-separated numbers, got {text!r}") from None
    if not weights:
        raise ParameterError("--weights is empty")
    for w in weights:
        if not (math.isfinite(w) and w >= 0.0):
            raise ParameterError(f"--weights must be finite and >= 0 per kJ, got {w!r}")
    return weights


def _check_outputs(paths: list[Path], inputs: list[Path], force: bool) -> None:
    from wheelloader.estimator.errors import ParameterError

    resolved_inputs = {p.resolve() for p in inputs if p.exists()}
    seen: set[Path] = set()
    for path in paths:
        if path.is_dir():
            raise ParameterError(f"output {path} is a directory; give a file name")
        if not path.parent.is_dir():
            raise ParameterError(f"output directory {path.parent} does not exist")
        if path.resolve() in resolved_inputs:
            raise ParameterError(f"output {path} is one of the input files; choose another name")
        if path.resolve() in seen:
            raise ParameterError(f"output {path} is given twice; choose different names")
        seen.add(path.resolve())
        if path.exists() and not force:
            raise ParameterError(f"output {path} exists; pass --force to replace it")


def write_plan_csv(csv_path: str | Path, path: Any, depth: np.ndarray, fill: np.ndarray, tangential: np.ndarray,
                   normal: np.ndarray) -> Path:
    """Write ``t, x, z, blade_angle, depth, fill, F_T, F_N`` [s, m, m, rad, m, m^3, N, N].

    The first four columns are those of :func:`~wheelloader.estimator.cyclelog.save_path_csv` (same
    number format), so :func:`~wheelloader.estimator.cyclelog.load_path_csv` reads the file as a path.
    """
    from wheelloader.estimator.cyclelog import write_columns

    csv_path = Path(csv_path)
    write_columns(csv_path, {"t": path.t, "x": path.x, "z": path.z, "blade_angle": path.blade_angle,
                             "depth": depth, "fill": fill, "F_T": tangential, "F_N": normal})
    return csv_path


def _describe(fill: float, capacity: float, energy: float) -> str:
    per = f"{energy / fill / 1e3:.1f} kJ/m^3" if fill > 0.0 else "n/a kJ/m^3 (nothing filled)"
    return f"fill {fill:.4f} m^3 ({fill / capacity:.0%}), energy {energy / 1e3:.2f} kJ, {per}"


def run_plan(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader plan``."""
    from wheelloader.adaptation import bezier_on_face
    from wheelloader.estimator.commands import load_pile
    from wheelloader.estimator.errors import ParameterError

    from .loop import cautious_options, cycle_duration, default_start, optimizer_for
    from .mpc import ACCEPTED_STATUSES
    from .pareto import pareto_sweep
    from .verify import path_energy, verify_plan

    if args.energy_weight is not None and not (math.isfinite(args.energy_weight) and args.energy_weight >= 0.0):
        raise ParameterError(f"--energy-weight must be a finite number >= 0 per kJ, got {args.energy_weight!r}")
    if not (math.isfinite(args.rate) and args.rate > 0.0):
        raise ParameterError(f"--rate must be > 0 Hz, got {args.rate!r}")
    if args.weights is not None and not args.pareto:
        raise ParameterError("--weights needs --pareto")
    weights = _parse_weights(args.weights) if args.pareto else ()
    output = Path(args.output)
    if output.name.lower().endswith(SUMMARY_SUFFIX) or output.suffix.lower() == ".json":
        raise ParameterError(f"output {output} should be a .csv file (the JSON summary is written beside it)")
    summary_path = output.with_name(output.stem + SUMMARY_SUFFIX)
    plot_path = Path(args.plot) if args.plot else None
    inputs = [Path(args.params)] + ([Path(args.pile)] if args.pile else [])
    _check_outputs([output, summary_path] + ([plot_path] if plot_path else []), inputs, args.force)

    soil = _load_soil(args.params)
    pile = load_pile(args.pile)
    timing: dict[str, float] = {}
    tic = time.perf_counter()
    opt = optimizer_for()
    timing["build_s"] = time.perf_counter() - tic
    lam = opt.options.energy_weight if args.energy_weight is None else float(args.energy_weight)
    start = default_start(pile)
    duration = cycle_duration(pile, start)
    plan = opt.solve(soil, pile, start, duration, energy_weight=lam)
    timing["solve_s"] = plan.solve_time
    tic = time.perf_counter()
    check = verify_plan(plan, soil, pile, opt.bucket, opt.loader, opt.options, rate=args.rate)
    timing["verify_s"] = time.perf_counter() - tic
    retried = None
    if not check.ok:
        # as plan_next_cycle: re-plan once with wider margins, starting from the plan that failed
        retried = list(check.failures)
        tic = time.perf_counter()
        opt = optimizer_for(opt.bucket, opt.loader, cautious_options(opt.options))
        timing["build_s"] += time.perf_counter() - tic
        plan = opt.solve(soil, pile, start, duration, energy_weight=lam, initial_guess=plan)
        timing["solve_s"] += plan.solve_time
        check = verify_plan(plan, soil, pile, opt.bucket, opt.loader, opt.options, rate=args.rate)
    path = plan.path(args.rate)
    sim = path_energy(path, soil, pile, opt.bucket)
    solver_ok = plan.status in ACCEPTED_STATUSES
    # as plan_next_cycle: a plan is usable when the NumPy check passes (if IPOPT stopped without success it
    # is feasible but not proven optimal, and the output says so)
    ok = check.ok
    cap = opt.bucket.capacity

    baseline = bezier_on_face(pile, args.rate, opt.bucket)
    base_check = verify_plan(baseline, soil, pile, opt.bucket, opt.loader, opt.options, rate=args.rate)

    points = []
    if args.pareto:
        tic = time.perf_counter()
        points = pareto_sweep(soil, pile, weights, start=start, options=opt.options, duration=duration,
                              rate=args.rate)
        timing["pareto_s"] = time.perf_counter() - tic

    state, forces = sim["state"], sim["forces"]
    write_plan_csv(output, path, state.depth, state.fill_volume, forces.tangential, forces.normal)
    summary: dict[str, Any] = {
        "params": str(args.params), "soil": soil.to_dict(), "pile": args.pile or "trapezoid",
        "energy_weight_per_kJ": lam, "duration_s": duration,
        "start": {"x": start.x, "z": start.z, "blade_angle": start.blade_angle},
        "ok": ok,
        "ok_definition": "the NumPy re-simulation passed every check; solver_ok false: feasible, not proven optimal",
        "replanned_with_wider_margins_after": retried,
        "plan": {"status": plan.status, "solver_ok": solver_ok, "iterations": plan.iterations,
                 "solve_time_s": plan.solve_time, "objective": plan.objective,
                 "predicted_energy_J_casadi": plan.energy, "predicted_fill_m3_casadi": plan.final_fill,
                 "fill_m3": check.fill, "fill_fraction": check.fill / cap, "energy_J": check.energy,
                 "energy_per_m3_J": check.energy / check.fill if check.fill > 0 else None,
                 "check": check.to_dict()},
        "baseline": {"name": baseline.name, "x_shift_m": float(baseline.x[0] - _default_x0(args.rate)),
                     "fill_m3": base_check.fill, "fill_fraction": base_check.fill / cap,
                     "energy_J": base_check.energy,
                     "energy_per_m3_J": base_check.energy / base_check.fill if base_check.fill > 0 else None,
                     "check": base_check.to_dict()},
        "pareto": [pt.to_dict() for pt in points],
        "timing_s": timing,
        "files": {"csv": str(output), "plot": str(plot_path) if plot_path else None},
        "energy_definition": "NumPy re-simulation at the CSV rate: sum of max(0, F_T ds_t + F_N ds_n) + "
                             "max(0, W_load dz) per step (the env's bookkeeping)",
    }
    summary_path.write_text(json.dumps(_clean(summary), indent=1, allow_nan=False))

    print(f"{args.params}: planned with lambda = {lam:g}/kJ on the {args.pile or 'trapezoid'} pile, "
          f"{duration:.2f} s cycle, {opt.intervals} intervals")
    print(f"timing: NLP build {timing['build_s'] * 1e3:.0f} ms (cached per settings), IPOPT "
          f"{timing['solve_s'] * 1e3:.0f} ms ({plan.iterations} it., {plan.status}), NumPy check "
          f"{timing['verify_s'] * 1e3:.0f} ms")
    print(f"plan (NumPy re-simulation): {_describe(check.fill, cap, check.energy)}; "
          f"peak F_T {check.max_tangential / 1e3:.1f} kN, peak F_N {check.max_normal / 1e3:.1f} kN")
    print(f"baseline ({baseline.name} path on this face): {_describe(base_check.fill, cap, base_check.energy)}"
          f"{'' if base_check.ok else '; fails: ' + '; '.join(base_check.failures)}")
    if retried is not None:
        print("first plan failed the NumPy check (" + "; ".join(retried) + "); re-planned once with wider margins")
    if check.ok:
        print("check: passed (forces, speeds, accelerations, validity domain, capacity, forward motion, end pose)")
    else:
        print("check: FAILED: " + "; ".join(check.failures))
    if not solver_ok:
        print(f"IPOPT did not succeed: {plan.status}"
              + ("; the plan is feasible by the NumPy check but not proven optimal" if check.ok else ""))
    if points:
        print(f"Pareto sweep over {len(points)} weights in {timing['pareto_s']:.1f} s:")
        print("  lambda/kJ   fill m^3  fill %   energy kJ   kJ/m^3  IPOPT status                  check")
        for pt in points:
            per = f"{pt.energy_per_m3 / 1e3:8.1f}" if math.isfinite(pt.energy_per_m3) else "     n/a"
            mark = "ok" if pt.check_ok else "FAILED: " + "; ".join(pt.failures)
            star = " *" if pt.pareto_optimal else ""
            print(f"  {pt.energy_weight:9g}  {pt.fill:9.4f}  {pt.fill_fraction:5.0%}  {pt.energy / 1e3:10.2f}  "
                  f"{per}  {pt.status:<28}  {mark}{star}")
        print("  (* = Pareto-optimal among the points that passed the check)")
    print(f"path written to {output}; summary written to {summary_path}")
    if plot_path is not None:
        from .plotting import plot_plan

        plot_plan(path, {"t": path.t, "F_T": forces.tangential, "F_N": forces.normal}, pile, opt.loader,
                  plot_path, baseline=baseline, pareto=points or None, chosen_weight=lam,
                  baseline_point=(base_check.fill, base_check.energy), plan_point=(check.fill, check.energy),
                  title=f"plan for {Path(str(args.params)).name}, lambda = {lam:g}/kJ")
        print(f"figure written to {plot_path}")
    if not ok:
        print("the plan was written but is NOT usable: it fails the NumPy check (see above and the summary)")
    return 0 if ok else 1


def _default_x0(rate: float) -> float:
    from wheelloader.estimator import default_path

    return float(default_path(rate=rate).x[0])


def _clean(obj: Any) -> Any:
    """JSON-ready copy: NumPy values as Python ones, non-finite floats as ``None``."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
