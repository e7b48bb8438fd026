"""``wheelloader calibrate`` and ``wheelloader predict``.

* ``wheelloader calibrate LOG.csv [LOG2.csv ...] [--method M] [--initial params.json] -o params.json
  [--plot fig.png]`` calibrates the soil from one logged cycle (CSV + JSON sidecar), or from several
  (oldest first, one soil fitted to all, ``--forgetting F`` weighs older cycles less), and prints
  timing, fit quality and what the cycle(s) determined.
* ``wheelloader predict params.json PATH.csv -o forces.csv [--pile P] [--plot fig.png]`` predicts the
  forces of a path. ``PATH.csv`` is either a path (columns ``t, x, z, blade_angle``; the pile comes from
  ``--pile``, default the trapezoid pile) or a cycle log (then its own pile is used unless ``--pile`` is
  given, and the RMSE against its measured forces is printed).
"""

from __future__ import annotations

import argparse
import logging
import math
import time
from pathlib import Path
from typing import Any

from .inputs import PILE_PRESETS, add_strict_flag, check_physical, is_cycle_log, load_pile, load_soil, sidecar_of
from .output import add_force_flag, write_json
from .staging import OutputRun, check_input_files


def register(subparsers: Any) -> None:
    """Add the ``calibrate`` and ``predict`` subcommands."""
    p = subparsers.add_parser("calibrate", help="calibrate the soil parameters from one logged cycle",
                              description="Calibrate the soil parameters from one logged cycle (CSV + JSON "
                                          "sidecar); print timing, fit quality and what the cycle determined.")
    p.add_argument("logs", nargs="+", metavar="log",
                   help="cycle log CSV (with its JSON sidecar of the same stem); several logs (oldest first) are "
                        "fitted together with one soil (varpro method)")
    p.add_argument("--forgetting", type=float,
                   help="several logs: forgetting factor in (0, 1]; the newest log weighs 1, the one before F, "
                        "then F^2, ... (default: all weigh 1)")
    p.add_argument("--method", default="varpro",
                   help="calibration method: varpro (ours, the default; alias 'default'), single-stage or "
                        "multi-stage (the paper's baselines; aliases 'single', 'multi')")
    p.add_argument("--initial", help="warm start: params.json of a previous cycle (or a soil preset name)")
    p.add_argument("--force-model", default="fee", metavar="NAME",
                   help="force model fitted: fee (the paper's, default) or fee-payload (the payload as a state: its "
                        "kept soil carried after the tip leaves the soil); params.json records it, and 'wheelloader "
                        "predict' and 'wheelloader plan' use it")
    p.add_argument("--sigma", type=float, default=3.0,
                   help="multi-stage stage-2 Gaussian filter sigma [samples] (default: %(default)s)")
    p.add_argument("--compare", action="store_true",
                   help="also run the other methods and show all side by side (output params: --method's)")
    p.add_argument("-o", "--output", default="params.json", help="output parameter file (default: %(default)s)")
    p.add_argument("--plot", help="write an observed-vs-predicted figure (PNG) like the paper's Figs. 6-7")
    add_strict_flag(p, "exit with status 1 when the fit is not trustworthy (the data could not determine the "
                       "soil), 2 when --initial holds parameters outside the physical domain")
    add_force_flag(p)
    p.set_defaults(func=run_calibrate)

    q = subparsers.add_parser("predict", help="predict the forces of a bucket path with calibrated parameters",
                              description="Predict the forces of a bucket path (a path CSV or a cycle log) "
                                          "with calibrated parameters.")
    q.add_argument("params", help="params.json from 'wheelloader calibrate' (or a bare 8-parameter JSON, "
                                  "or a soil preset name)")
    q.add_argument("path", help="path CSV (t, x, z, blade_angle) or a cycle log CSV")
    q.add_argument("-o", "--output", default="forces.csv", help="output CSV (default: %(default)s)")
    q.add_argument("--pile", help="pile: JSON file with {\"x\": [...], \"z\": [...]} (or a cycle-log sidecar), "
                                  f"or a preset: {', '.join(PILE_PRESETS)} (default: the log's pile, else trapezoid)")
    q.add_argument("--plot", help="write a figure of the predicted (and observed) forces (PNG), with the "
                                  "prediction band when the params file has one")
    q.add_argument("--band", type=float, default=0.9,
                   help="level of the prediction band (from the calibration's parameter covariance and residual "
                        "noise model; params.json from 'wheelloader calibrate' only) (default: %(default)s; 0: none)")
    add_strict_flag(q, "refuse parameters outside the physical domain (exit status 2) instead of warning")
    add_force_flag(q)
    q.set_defaults(func=run_predict)


def _check_sigma(sigma: float, samples: int) -> None:
    from wheelloader.estimator import ParameterError

    if not (math.isfinite(sigma) and 0.0 <= sigma <= samples):
        raise ParameterError(f"--sigma must be a number of samples between 0 and the log's length ({samples}), "
                             f"got {sigma!r}")


def _refuse_repeated_logs(logs: list[str]) -> None:
    """The same cycle given twice (by name, symlink or hard link) would count as two cycles."""
    import os

    from wheelloader.estimator import ParameterError

    seen: dict[object, str] = {}
    for log in logs:
        try:
            st = os.stat(log)
        except OSError:
            continue  # the reader reports a missing file
        key = (st.st_dev, st.st_ino)
        if key in seen:
            raise ParameterError(f"log {log} is the same file as {seen[key]}; each cycle counts once, give it once")
        seen[key] = log


def run_calibrate(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader calibrate``."""
    from wheelloader.estimator import (
        METHODS,
        CalibrationError,
        CalibrationOptions,
        CycleLog,
        calibrate,
        canonical_method,
    )

    method = canonical_method(args.method)
    several = len(args.logs) > 1
    if several and method != "varpro":
        raise CalibrationError(f"several logs are fitted together by the varpro method only, not {method!r}")
    if several and args.compare:
        raise CalibrationError("--compare needs one log (the paper's methods calibrate on one cycle)")
    if args.forgetting is not None and not several:
        raise CalibrationError("--forgetting needs several logs")
    inputs = [*args.logs, *(sidecar_of(log) for log in args.logs), args.initial]
    check_input_files([*(("log", p) for p in args.logs), *(("sidecar", sidecar_of(p)) for p in args.logs),
                       ("--initial", args.initial)])
    _refuse_repeated_logs(args.logs)
    run = OutputRun(force=args.force, inputs=inputs)
    run.file("-o/--output", args.output)
    run.file("--plot", args.plot)
    cycles = [CycleLog.load(log) for log in args.logs]
    cycle = cycles[0]
    _check_sigma(args.sigma, len(cycle))
    initial = check_physical(load_soil(args.initial), "--initial", args.strict) if args.initial else None
    with run:
        model = {"force_model": args.force_model}
        if several:
            cal = calibrate(cycles, options=CalibrationOptions(method=method, initial=initial,
                                                               forgetting=args.forgetting, **model))
        else:
            cal = calibrate(cycle, options=CalibrationOptions(method=method, initial=initial, sigma=args.sigma,
                                                              **model))
        others = []
        if args.compare:
            others = [calibrate(cycle, options=CalibrationOptions(method=m, initial=initial, sigma=args.sigma,
                                                                  **model))
                      for m in METHODS if m != cal.method]
        write_json(run.staged(args.output), cal.to_dict())
        if args.plot:
            from wheelloader.plotting import plot_calibration, plot_cycles_fit

            if several:
                plot_cycles_fit(cycles, cal, run.staged(args.plot), title=f"calibration on {len(cycles)} cycles")
            else:
                plot_calibration(cycle, [cal, *others], run.staged(args.plot),
                                 title=f"calibration of {Path(args.logs[0]).name}")
    if several:
        for k, (log, c) in enumerate(zip(args.logs, cycles, strict=True)):
            print(f"{log}: {len(c)} samples, {cal.settings['cycles']['per_cycle'][k]['samples']} in soil")
    else:
        decimation = cal.settings.get("decimation")
        if decimation:  # the fit used every stride-th in-soil sample; the log's own count is the one printed
            print(f"{args.logs[0]}: {len(cycle)} samples, {decimation['in_soil_samples']} in soil (every "
                  f"{decimation['stride']}-th fitted: {int(cal.in_soil.sum())})")
        else:
            print(f"{args.logs[0]}: {len(cycle)} samples, {int(cal.in_soil.sum())} in soil")
    print(cal.summary())
    for other in others:
        flag = "converged" if other.success else "NOT CONVERGED"
        print(f"compare {other.method:>12}: {other.time_s * 1e3:8.1f} ms, {other.nfev:6d} evals, {flag}; "
              f"{other.quality.describe()}")
    print(f"parameters written to {args.output}")
    if args.plot:
        print(f"figure written to {args.plot}")
    if not cal.trustworthy:
        print("the fit is NOT trustworthy: " + "; ".join(w.message for w in cal.warnings)
              + ("" if args.strict else " (--strict makes this exit status 1)"))
    return 0 if cal.success and (cal.trustworthy or not args.strict) else 1


def run_predict(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader predict``."""
    import numpy as np

    from wheelloader.estimator import CycleLog, ParameterError, load_path_csv, predict

    path_file = Path(args.path)
    inputs = [args.params, path_file, sidecar_of(path_file), args.pile]
    check_input_files([("params", args.params), ("path", path_file), ("sidecar", sidecar_of(path_file)),
                       ("--pile", args.pile)])
    run = OutputRun(force=args.force, inputs=inputs)
    run.file("-o/--output", args.output)
    run.file("--plot", args.plot)
    from wheelloader.estimator.calibration.result import SavedModel, load_saved_model

    if not (0.0 <= args.band < 1.0):
        raise ParameterError(f"--band must be a level in [0, 1) (0: no band), got {args.band!r}")
    soil = check_physical(load_soil(args.params), args.params, args.strict)
    saved = load_saved_model(args.params) if Path(args.params).is_file() else SavedModel()
    pile = None if args.pile is None else load_pile(args.pile)
    start = time.perf_counter()
    if is_cycle_log(path_file):
        target = CycleLog.load(path_file)
        pile_used = pile if pile is not None else target.pile
    else:
        target = load_path_csv(path_file)
        from wheelloader.estimator.plausibility import check_path

        for warning in check_path(target, str(path_file)):
            logging.getLogger("wheelloader.cli").warning("warning: %s: %s", path_file, warning)
        pile = load_pile(None) if pile is None else pile
        pile_used = pile
    band = args.band if args.band > 0.0 and saved.band_model is not None else None
    with run:
        pred = predict(soil, target, pile=pile, options=saved.options, fill=saved.fill, band=band,
                       band_model=saved.band_model, force_model=saved.force_model, payload=saved.payload)
        elapsed = time.perf_counter() - start
        pred.save_csv(run.staged(args.output), overwrite=True)
        if args.plot:
            from wheelloader.plotting import plot_prediction

            plot_prediction(pred, pile_used, run.staged(args.plot), title=f"prediction for {path_file.name}")
    f = pred.forces
    print(f"{path_file.name}: {len(pred.path)} samples, {int((pred.state.depth > 0).sum())} in soil; "
          f"predicted in {elapsed * 1e3:.1f} ms")
    print(f"peak F_T {f.tangential.max():.0f} N, peak F_N {f.normal.max():.0f} N, peak F_R {f.resultant.max():.0f} N")
    flagged = {k: v for k, v in f.flag_summary().items() if v and k != "tip out of soil"}
    if flagged:
        print("samples outside the model's validity domain: " + ", ".join(f"{k}: {v}" for k, v in flagged.items()))
    if pred.quality is not None:
        print(pred.quality.describe())
    if pred.band is not None:
        mask = pred.state.depth > 0.0
        line = f"{pred.band.level:.0%} prediction band computed"
        if np.any(mask):
            half = float(np.mean(pred.band.upper_r[mask] - pred.resultant[mask]))
            line = f"{pred.band.level:.0%} prediction band: mean half-width {half:.0f} N in soil"
        if pred.observed_tangential is not None and np.any(mask):
            obs = np.hypot(pred.observed_tangential, pred.observed_normal)
            line += f"; covers {pred.band.coverage(obs, mask):.0%} of the measured in-soil F_R"
        print(line)
    elif args.band > 0.0:
        print("no prediction band: the params file holds no band model (write it with 'wheelloader calibrate')")
    print(f"forces written to {args.output}")
    if args.plot:
        print(f"figure written to {args.plot}")
    return 0
