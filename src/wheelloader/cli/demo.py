"""``wheelloader demo``: the cycle-to-cycle adaptation loop on the built-in default (``wheelloader.demo``)."""

from __future__ import annotations

import argparse
from typing import Any

from .output import add_force_flag, fresh_directory


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    from wheelloader.demo import DEFAULT_CYCLES

    p = subparsers.add_parser("demo", help="run the cycle-to-cycle adaptation demo on the built-in default",
                              description="Run the cycle-to-cycle adaptation loop (calibrate, predict, plan, dig) "
                                          "on the built-in default pile and hidden soil, beside the fixed path.")
    p.add_argument("-o", "--out", default="wheelloader-demo",
                   help="output directory (a new NAME-2, NAME-3 ... is used if it exists; default: %(default)s)")
    p.add_argument("--cycles", type=int, default=DEFAULT_CYCLES, help="digging cycles (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the plant (default: %(default)s)")
    p.add_argument("--no-planner", action="store_true",
                   help="dig the Bezier path every cycle (calibration and prediction only)")
    p.add_argument("--window", type=int, default=None,
                   help="calibrate on the last WINDOW cycles together (default: "
                        "wheelloader.adaptation.DEFAULT_WINDOW)")
    p.add_argument("--mpc", action="store_true",
                   help="execute each plan with the receding-horizon MPC instead of tracking it (slower)")
    p.add_argument("--plant", choices=("fee-env", "mpm"), default="fee-env",
                   help="where the cycles are dug: the FEE env (default, seconds) or the MPM continuum reference "
                        "(needs the mpm extra; about 3 minutes per cycle at 2 cm, 2 x CYCLES cycles; resumable)")
    p.add_argument("--resolution", type=float, default=0.02,
                   help="MPM grid spacing [m] with --plant mpm (default: %(default)s, the verified one)")
    add_force_flag(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader demo``."""
    from wheelloader.demo import run_demo
    from wheelloader.estimator import ParameterError

    if args.cycles < 1 or args.cycles > 50:
        raise ParameterError(f"--cycles must be between 1 and 50, got {args.cycles}")
    if not 0.005 <= args.resolution <= 0.1:
        raise ParameterError(f"--resolution must be between 0.005 and 0.1 m, got {args.resolution}")
    if args.window is not None and args.window < 1:
        raise ParameterError(f"--window must be a positive number of cycles, got {args.window}")
    out = fresh_directory(args.out, args.force)
    summary = run_demo(out, cycles=args.cycles, seed=args.seed, use_planner=not args.no_planner,
                       progress=lambda line: print(line, flush=True), mpc=args.mpc, plant=args.plant,
                       resolution=args.resolution, window=args.window)
    print()
    print(summary["table"])
    print()
    for name in ("summary.json", summary["table_markdown"], *summary["figures"]):
        print(f"wrote {out / name}")
    print(f"results written to {out.resolve()}")
    return 0
