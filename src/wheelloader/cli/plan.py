"""``wheelloader plan``: the next cycle's bucket path for a calibration and a pile.

``wheelloader plan params.json [--pile P] [--energy-weight L] [--pareto] -o plan.csv [--plot plan.png]``
plans a full cycle with :func:`~wheelloader.planner.plan_next_cycle` (the planner of the cycle-to-cycle
loop: CasADi/IPOPT, re-simulated with the NumPy force model, every constraint checked, re-planned with
wider margins when the check fails), writes the path with the predicted forces as CSV (``t, x, z,
blade_angle, depth, fill, F_T, F_N``; readable by ``wheelloader predict`` as a path) and a JSON summary
beside it (``plan.summary.json``), and prints timing, fill, energy, energy per m^3 and the check result
next to the paper's default Bezier path on the same face. ``--pareto`` adds a sweep over the energy
weight (fill against energy).

A plan that passes the check is usable even when IPOPT stopped without success (then it is reported as
feasible but not proven optimal). Exit status 0 when the plan passed the check, 1 when it was written
but failed (the summary says why), 2 for bad input.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from .inputs import PILE_PRESETS, add_strict_flag, check_physical, load_pile, load_soil
from .output import add_force_flag, write_json
from .staging import OutputRun, check_input_files

#: Summary file written beside the CSV: ``plan.csv`` -> ``plan.summary.json`` (not ``plan.json``, which
#: would make the CSV look like a cycle log to ``wheelloader predict``).
SUMMARY_SUFFIX = ".summary.json"
#: Sampling rates the CSV and the check accept [Hz].
RATE_RANGE = (5.0, 1000.0)


def register(subparsers: Any) -> None:
    """Add the ``plan`` subcommand."""
    p = subparsers.add_parser("plan", help="plan the next cycle's bucket path (fill against energy)",
                              description="Plan the next cycle's bucket path for a calibration and a pile; "
                                          "check it with the NumPy force model; write CSV + JSON summary.")
    p.add_argument("params", help="params.json from 'wheelloader calibrate' (or a bare 8-parameter JSON, "
                                  "or a soil preset name such as gravel)")
    p.add_argument("--pile", help="pile: JSON file with {\"x\": [...], \"z\": [...]} (or a cycle-log sidecar), "
                                  f"or a preset: {', '.join(PILE_PRESETS)} (default: trapezoid)")
    p.add_argument("--energy-weight", type=float, default=None, metavar="L",
                   help="energy weight lambda per kJ, in bucket-fills (default: the planner's, 0.02)")
    p.add_argument("--pareto", action="store_true", help="also sweep lambda and report fill against energy")
    p.add_argument("--weights", default=None, metavar="L1,L2,...",
                   help="comma-separated lambdas of the --pareto sweep (default: 0,0.005,0.01,0.02,0.05,0.1,0.2)")
    p.add_argument("--rate", type=float, default=60.0,
                   help=f"sampling rate of the CSV and the check, {RATE_RANGE[0]:g}-{RATE_RANGE[1]:g} Hz "
                        "(default: %(default)s)")
    p.add_argument("--max-time", type=float, default=None, metavar="SECONDS",
                   help="opt-in wall-time cap of each IPOPT solve; the result then depends on the machine's "
                        "speed, and the output says when it fired (default: none, an iteration limit only)")
    p.add_argument("-o", "--output", default="plan.csv", help="output path CSV (default: %(default)s); "
                                                              f"the summary goes beside it as *{SUMMARY_SUFFIX}")
    p.add_argument("--plot", help="write a figure (PNG): path, predicted forces and limits (+ Pareto front)")
    add_strict_flag(p, "refuse parameters outside the physical domain (exit status 2) instead of warning")
    add_force_flag(p)
    p.set_defaults(func=run_plan)


def _parse_weights(text: str | None) -> tuple[float, ...]:
    from wheelloader.estimator import ParameterError
    from wheelloader.planner import DEFAULT_WEIGHTS

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


def _validate(args: argparse.Namespace) -> None:
    from wheelloader.estimator import ParameterError

    if args.energy_weight is not None and not (math.isfinite(args.energy_weight) and args.energy_weight >= 0.0):
        raise ParameterError(f"--energy-weight must be a finite number >= 0 per kJ, got {args.energy_weight!r}")
    if not (math.isfinite(args.rate) and RATE_RANGE[0] <= args.rate <= RATE_RANGE[1]):
        raise ParameterError(f"--rate must be between {RATE_RANGE[0]:g} and {RATE_RANGE[1]:g} Hz, got {args.rate!r}")
    if args.max_time is not None and not (math.isfinite(args.max_time) and args.max_time > 0.0):
        raise ParameterError(f"--max-time must be a number of seconds > 0, got {args.max_time!r}")
    if args.weights is not None and not args.pareto:
        raise ParameterError("--weights needs --pareto")


def _describe(fill: float, capacity: float, energy: float) -> str:
    per = f"{energy / fill / 1e3:.1f} kJ/m^3" if fill > 0.0 else "n/a kJ/m^3 (nothing filled)"
    return f"fill {fill:.4f} m^3 ({fill / capacity:.0%}), energy {energy / 1e3:.2f} kJ, {per}"


def _per_m3(energy: float, fill: float) -> float | None:
    return energy / fill if fill > 0 else None


def _output_paths(given: str) -> tuple[Path, Path]:
    """The CSV path ``-o/--output`` names and the JSON summary's beside it (a clear error for a bad name)."""
    from wheelloader.estimator import ParameterError

    output = Path(given)
    if output.name in ("", ".", ".."):
        raise ParameterError(f"-o/--output {given!r} is not a file name")
    if output.name.lower().endswith(SUMMARY_SUFFIX) or output.suffix.lower() == ".json":
        raise ParameterError(f"output {output} should be a .csv file (the JSON summary is written beside it)")
    return output, output.with_name(output.stem + SUMMARY_SUFFIX)


def _summary(args: argparse.Namespace, *, soil, lam: float, duration: float, start, ok: bool, outcome,
             solver_ok: bool, cap: float, baseline, base_check, points: list, timing: dict[str, float],
             nlp_origin: str, output: Path, force_model: str = "fee") -> dict[str, Any]:
    """The JSON summary of ``wheelloader plan``."""
    from wheelloader.estimator import default_path

    plan, check, retried = outcome.plan, outcome.check, outcome.first_failures or None
    return {
        "params": str(args.params), "soil": soil.to_dict(), "pile": args.pile or "trapezoid",
        "force_model": force_model,
        "energy_weight_per_kJ": lam, "duration_s": duration, "max_time_s": args.max_time,
        "start": {"x": start.x, "z": start.z, "blade_angle": start.blade_angle},
        "ok": ok,
        "ok_definition": "the NumPy re-simulation passed every check; solver_ok false: feasible, not proven "
                         "optimal",
        "replanned_with_wider_margins_after": retried,
        "message": outcome.message,
        "plan": {"status": plan.status, "solver_ok": solver_ok, "iterations": plan.iterations,
                 "solve_time_s": plan.solve_time, "objective": plan.objective,
                 "predicted_energy_J_casadi": plan.energy, "predicted_fill_m3_casadi": plan.final_fill,
                 "fill_m3": check.fill, "carved_m3": check.carved, "fill_fraction": check.fill / cap,
                 "energy_J": check.energy,
                 "energy_per_m3_J": _per_m3(check.energy, check.fill), "check": check.to_dict()},
        "baseline": {"name": baseline.name, "x_shift_m": float(baseline.x[0] - default_path(rate=args.rate).x[0]),
                     "fill_m3": base_check.fill, "fill_fraction": base_check.fill / cap,
                     "energy_J": base_check.energy, "energy_per_m3_J": _per_m3(base_check.energy, base_check.fill),
                     "check": base_check.to_dict()},
        "pareto": [pt.to_dict() for pt in points],
        "timing_s": timing,
        "nlp": nlp_origin,
        "files": {"csv": str(output), "plot": args.plot},
        "energy_definition": "NumPy re-simulation at the CSV rate: sum of max(0, F_T ds_t + F_N ds_n) + "
                             "max(0, W_load dz) per step (the env's bookkeeping)",
    }


def _planner_options(args: argparse.Namespace):
    """The planner's options: ``--max-time`` and the calibration's force model (params.json records it; the
    paper's FEE for a bare parameter file or a preset)."""
    from wheelloader.estimator.calibration.result import SavedModel, load_saved_model
    from wheelloader.planner import PlannerOptions

    saved = load_saved_model(args.params) if Path(args.params).is_file() else SavedModel()
    return PlannerOptions(max_wall_time=args.max_time, force_model=saved.force_model or "fee", payload=saved.payload)


def _print_head(args: argparse.Namespace, lam: float, duration: float, opt, timing: dict[str, float],
                nlp_origin: str, plan) -> None:
    """Print what was planned (weight, pile, duration, force model) and how long it took."""
    model = opt.options.force_model
    print(f"{args.params}: planned with lambda = {lam:g}/kJ on the {args.pile or 'trapezoid'} pile, "
          f"{duration:.2f} s cycle, {opt.intervals} intervals"
          + ("" if model == "fee" else f", force model {model} (the fill is the payload's kept soil)"))
    how = "loaded from the on-disk cache" if nlp_origin.startswith("loaded") else nlp_origin.split(" in ")[0]
    print(f"timing: NLP {timing['build_s'] * 1e3:.0f} ms ({how}), planning "
          f"{timing['plan_s'] * 1e3:.0f} ms (IPOPT {plan.iterations} it., {plan.status}, and the NumPy check)")


def _print_verdict(ok: bool, outcome, solver_ok: bool, max_time: float | None) -> None:
    """Print whether the plan passed the NumPy check and how IPOPT ended."""
    plan, check = outcome.plan, outcome.check
    if ok:
        print("check: passed (forces, speeds, accelerations, validity domain, capacity, forward motion, end pose)")
    elif check.ok:
        print(f"check: FAILED: {outcome.message}")
    else:
        print("check: FAILED: " + "; ".join(check.failures))
    if not solver_ok:
        print(f"IPOPT did not succeed: {plan.status}"
              + ("; the plan is feasible by the NumPy check but not proven optimal" if check.ok else ""))
    if plan.status == "Maximum_WallTime_Exceeded":
        print(f"the --max-time cap of {max_time:g} s fired: this result depends on the machine's speed")


def _print_pareto(points: list, seconds: float) -> None:
    """Print the Pareto sweep's table."""
    print(f"Pareto sweep over {len(points)} weights in {seconds:.1f} s:")
    print("  lambda/kJ   fill m^3  fill %   energy kJ   kJ/m^3  IPOPT status                  check")
    for pt in points:
        per = f"{pt.energy_per_m3 / 1e3:8.1f}" if math.isfinite(pt.energy_per_m3) else "     n/a"
        mark = "ok" if pt.check_ok else "FAILED: " + "; ".join(pt.failures)
        star = " *" if pt.pareto_optimal else ""
        print(f"  {pt.energy_weight:9g}  {pt.fill:9.4f}  {pt.fill_fraction:5.0%}  {pt.energy / 1e3:10.2f}  "
              f"{per}  {pt.status:<28}  {mark}{star}")
    print("  (* = Pareto-optimal among the points that passed the check)")


def run_plan(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader plan``."""
    from wheelloader.estimator import PlanningError
    from wheelloader.estimator.cyclelog import write_columns
    from wheelloader.planner import (
        bezier_on_face,
        cycle_duration,
        default_start,
        optimizer_for,
        pareto_sweep,
        path_energy,
        plan_next_cycle,
        verify_plan,
    )
    from wheelloader.planner.mpc import ACCEPTED_STATUSES
    from wheelloader.planner.nlp import origin

    _validate(args)
    weights = _parse_weights(args.weights) if args.pareto else ()
    output, summary_path = _output_paths(args.output)
    check_input_files([("params", args.params), ("--pile", args.pile)])
    run = OutputRun(force=args.force, inputs=[args.params, args.pile])
    for flag, value in (("-o/--output", output), ("summary", summary_path), ("--plot", args.plot)):
        run.file(flag, value)

    soil = check_physical(load_soil(args.params), args.params, args.strict)
    pile = load_pile(args.pile)
    with run:
        options = _planner_options(args)
        timing: dict[str, float] = {}
        tic = time.perf_counter()
        opt = optimizer_for(options=options)
        timing["build_s"] = time.perf_counter() - tic
        nlp_origin = origin(opt.bucket, opt.loader, opt.options) or "built earlier in this process"
        lam = opt.options.energy_weight if args.energy_weight is None else float(args.energy_weight)
        start = default_start(pile)
        duration = cycle_duration(pile, start)
        outcome = plan_next_cycle(soil, pile, start=start, options=options, control_rate=args.rate, mpc=False,
                                  energy_weight=lam)
        timing["plan_s"] = outcome.seconds
        if outcome.plan is None or outcome.check is None:
            raise PlanningError(outcome.message)
        plan, check = outcome.plan, outcome.check
        path = plan.path(args.rate)
        sim = path_energy(path, soil, pile, opt.bucket, model_options=opt.options.model_options,
                          payload=opt.options.force_payload, learned=opt.options.force_model == "fee-learned")
        solver_ok = plan.status in ACCEPTED_STATUSES
        # the check judges forces, limits and poses; a plan can pass it and still load (almost) nothing, which
        # plan_next_cycle does not accept (outcome.success false): usable needs both
        ok = check.ok and outcome.success
        cap = opt.bucket.capacity
        retried = outcome.first_failures or None

        baseline = bezier_on_face(pile, args.rate, opt.bucket)
        base_check = verify_plan(baseline, soil, pile, opt.bucket, opt.loader, opt.options, rate=args.rate)

        points = []
        if args.pareto:
            tic = time.perf_counter()
            points = pareto_sweep(soil, pile, weights, start=start, options=opt.options, duration=duration,
                                  rate=args.rate)
            timing["pareto_s"] = time.perf_counter() - tic

        state, forces = sim["state"], sim["forces"]
        summary = _summary(args, soil=soil, lam=lam, duration=duration, start=start, ok=ok, outcome=outcome,
                           solver_ok=solver_ok, cap=cap, baseline=baseline, base_check=base_check, points=points,
                           timing=timing, nlp_origin=nlp_origin, output=output,
                           force_model=opt.options.force_model)
        # the first four columns are save_path_csv's, so load_path_csv reads the file as a path
        write_columns(run.staged(output), {"t": path.t, "x": path.x, "z": path.z, "blade_angle": path.blade_angle,
                                           "depth": state.depth, "fill": sim["fill_history"], "F_T": forces.tangential,
                                           "F_N": forces.normal})
        write_json(run.staged(summary_path), summary)
        if args.plot:
            from wheelloader.plotting import plot_plan

            plot_plan(path, {"t": path.t, "F_T": forces.tangential, "F_N": forces.normal}, pile, opt.loader,
                      run.staged(args.plot), baseline=baseline, pareto=points or None, chosen_weight=lam,
                      baseline_point=(base_check.fill, base_check.energy), plan_point=(check.fill, check.energy),
                      title=f"plan for {Path(str(args.params)).name}, λ = {lam:g}/kJ")

    _print_head(args, lam, duration, opt, timing, nlp_origin, plan)
    print(f"plan (NumPy re-simulation): {_describe(check.fill, cap, check.energy)}; "
          f"peak F_T {check.max_tangential / 1e3:.1f} kN, peak F_N {check.max_normal / 1e3:.1f} kN")
    print(f"baseline ({baseline.name} path on this face): {_describe(base_check.fill, cap, base_check.energy)}"
          f"{'' if base_check.ok else '; fails: ' + '; '.join(base_check.failures)}")
    if retried is not None:
        print("first plan failed the NumPy check (" + "; ".join(retried) + "); re-planned with wider margins")
    _print_verdict(ok, outcome, solver_ok, args.max_time)
    if points:
        _print_pareto(points, timing["pareto_s"])
    print(f"path written to {output}; summary written to {summary_path}")
    if args.plot:
        print(f"figure written to {args.plot}")
    if not ok:
        print("the plan was written but is NOT usable: it fails the NumPy check (see above and the summary)")
    return 0 if ok else 1
