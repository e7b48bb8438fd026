"""``wheelloader calibrate`` and ``wheelloader predict``.

* ``wheelloader calibrate LOG.csv [--method M] [--initial params.json] -o params.json [--plot fig.png]``
  calibrates the soil from one logged cycle (CSV + JSON sidecar) and prints
  timing, fit quality and what the cycle determined.
* ``wheelloader predict params.json PATH.csv -o forces.csv [--pile P] [--plot fig.png]``
  predicts the forces of a path. ``PATH.csv`` is either a path (columns
  ``t, x, z, blade_angle``; the pile comes from ``--pile``, default the
  trapezoid pile) or a cycle log (then its own pile is used unless
  ``--pile`` is given, and the RMSE against its measured forces is printed).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

PILE_PRESETS = ("trapezoid", "slope")


def register(subparsers: Any) -> None:
    """Add the ``calibrate`` and ``predict`` subcommands."""
    p = subparsers.add_parser("calibrate", help="calibrate the soil parameters from one logged cycle",
                              description=__doc__.splitlines()[2].strip("* "))
    p.add_argument("log", help="cycle log CSV (with its JSON sidecar of the same stem)")
    p.add_argument("--method", default="default", choices=["default", "single-stage", "multi-stage"],
                   help="calibration method (default: %(default)s; the others are the paper's baselines)")
    p.add_argument("--initial", help="warm start: params.json of a previous cycle (or a soil preset name)")
    p.add_argument("--sigma", type=float, default=3.0,
                   help="multi-stage stage-2 Gaussian filter sigma [samples] (default: %(default)s)")
    p.add_argument("--compare", action="store_true",
                   help="also run the other methods and show all side by side (output params: --method's)")
    p.add_argument("-o", "--output", default="params.json", help="output parameter file (default: %(default)s)")
    p.add_argument("--plot", help="write an observed-vs-predicted figure (PNG) like the paper's Figs. 6-7")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.set_defaults(func=run_calibrate)

    q = subparsers.add_parser("predict", help="predict the forces of a bucket path with calibrated parameters",
                              description=__doc__.splitlines()[5].strip("* "))
    q.add_argument("params", help="params.json from 'wheelloader calibrate' (or a bare 8-parameter JSON, "
                                  "or a soil preset name)")
    q.add_argument("path", help="path CSV (t, x, z, blade_angle) or a cycle log CSV")
    q.add_argument("-o", "--output", default="forces.csv", help="output CSV (default: %(default)s)")
    q.add_argument("--pile", help="pile: JSON file with {\"x\": [...], \"z\": [...]} (or a cycle-log sidecar), "
                                  f"or a preset: {', '.join(PILE_PRESETS)} (default: the log's pile, else trapezoid)")
    q.add_argument("--plot", help="write a figure of the predicted (and observed) forces (PNG)")
    q.add_argument("--overwrite", action="store_true", help="replace existing output files")
    q.set_defaults(func=run_predict)


def _check_output(path: str | None, overwrite: bool) -> None:
    from wheelloader.estimator.errors import ParameterError

    if path is None:
        return
    if Path(path).is_dir():
        raise ParameterError(f"output {path} is a directory; give a file name")
    if Path(path).exists() and not overwrite:
        raise ParameterError(f"output {path} exists; pass --overwrite to replace it")
    parent = Path(path).parent
    if not parent.is_dir():
        raise ParameterError(f"output directory {parent} does not exist")


def run_calibrate(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader calibrate``."""
    from wheelloader.estimator.calibration import calibrate, load_params
    from wheelloader.estimator.cyclelog import CycleLog

    cycle = CycleLog.load(args.log)
    _check_output(args.output, args.overwrite)
    _check_output(args.plot, args.overwrite)
    initial = load_params(args.initial) if args.initial else None
    cal = calibrate(cycle, args.method, initial=initial, sigma=args.sigma)
    others = []
    if args.compare:
        others = [calibrate(cycle, m, initial=initial, sigma=args.sigma)
                  for m in ("default", "single-stage", "multi-stage") if m != cal.method]
    print(f"{args.log}: {len(cycle)} samples, {int(cal.in_soil.sum())} in soil")
    print(cal.summary())
    for other in others:
        flag = "converged" if other.success else "NOT CONVERGED"
        print(f"compare {other.method:>12}: {other.time_s * 1e3:8.1f} ms, {other.nfev:6d} evals, {flag}; "
              f"{other.quality.describe()}")
    cal.save_json(args.output)
    print(f"parameters written to {args.output}")
    if args.plot:
        from wheelloader.estimator.plotting import plot_calibration

        plot_calibration(cycle, [cal, *others], args.plot, title=f"calibration of {Path(args.log).name}")
        print(f"figure written to {args.plot}")
    return 0 if cal.success else 1


def load_pile(spec: str | None):
    """A :class:`Pile` from a JSON file path or a preset name (``None``: the trapezoid)."""
    from wheelloader.estimator.errors import ParameterError
    from wheelloader.estimator.pile import Pile

    if spec is None or spec == "trapezoid":
        return Pile.trapezoid()
    if spec in ("slope", "ideal_slope"):
        return Pile.ideal_slope()
    path = Path(spec)
    if not path.exists():
        raise ParameterError(f"--pile {spec!r} is neither a file nor a preset ({', '.join(PILE_PRESETS)})")
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError, IsADirectoryError) as exc:
        raise ParameterError(f"{path}: not a valid JSON file ({exc})") from None
    if isinstance(data, dict) and isinstance(data.get("pile"), dict):
        data = data["pile"]  # a cycle-log sidecar
    try:
        return Pile.from_dict(data)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None


def _is_cycle_log(path: Path) -> bool:
    if not path.with_suffix(".json").exists() or not path.is_file():
        return False
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    header = [h.strip() for h in line.split(",")]
                    return "F_T" in header and "F_N" in header
    except UnicodeDecodeError:
        return False  # reading it as a path CSV then reports the problem
    return False


def run_predict(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader predict``."""
    import time

    from wheelloader.estimator.calibration import load_params, predict
    from wheelloader.estimator.cyclelog import CycleLog, load_path_csv

    _check_output(args.output, args.overwrite)
    _check_output(args.plot, args.overwrite)
    soil = load_params(args.params)
    path_file = Path(args.path)
    pile = None if args.pile is None else load_pile(args.pile)
    start = time.perf_counter()
    if _is_cycle_log(path_file):
        target = CycleLog.load(path_file)
        pile_used = pile if pile is not None else target.pile
    else:
        target = load_path_csv(path_file)
        pile = load_pile(None) if pile is None else pile
        pile_used = pile
    pred = predict(soil, target, pile=pile)
    elapsed = time.perf_counter() - start
    pred.save_csv(args.output, overwrite=True)
    f = pred.forces
    print(f"{path_file.name}: {len(pred.path)} samples, {int((pred.state.depth > 0).sum())} in soil; "
          f"predicted in {elapsed * 1e3:.1f} ms")
    print(f"peak F_T {f.tangential.max():.0f} N, peak F_N {f.normal.max():.0f} N, peak F_R {f.resultant.max():.0f} N")
    flagged = {k: v for k, v in f.flag_summary().items() if v and k != "tip out of soil"}
    if flagged:
        print("samples outside the model's validity domain: " + ", ".join(f"{k}: {v}" for k, v in flagged.items()))
    if pred.quality is not None:
        print(pred.quality.describe())
    print(f"forces written to {args.output}")
    if args.plot:
        from wheelloader.estimator.plotting import plot_prediction

        plot_prediction(pred, pile_used, args.plot, title=f"prediction for {path_file.name}")
        print(f"figure written to {args.plot}")
    return 0
