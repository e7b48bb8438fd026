"""``wheelloader demo``: the cycle-to-cycle adaptation loop on the built-in default (``wheelloader.demo``)."""

from __future__ import annotations

import argparse
import math
import shutil
from typing import Any

from .output import add_force_flag
from .staging import OutputRun


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    from wheelloader.demo import DEFAULT_CYCLES, DEFAULT_SEEDS, DEMO_PLANTS, DEMO_PRIOR

    p = subparsers.add_parser("demo", help="run the cycle-to-cycle adaptation demo on the built-in default",
                              description="Run the cycle-to-cycle adaptation loop (calibrate, predict, plan, dig) "
                                          "on the built-in default pile and hidden soil, beside the fixed path.")
    p.add_argument("-o", "--out", default="wheelloader-demo",
                   help="output directory (a new NAME-2, NAME-3 ... is used if it exists; default: %(default)s)")
    p.add_argument("--cycles", type=int, default=DEFAULT_CYCLES, help="digging cycles (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="random seed of the plant, 0 to 2^32 - 1 (default: %(default)s)")
    p.add_argument("--seeds", type=int, default=None,
                   help=f"plant seeds SEED, SEED+1, ...: the table gives each cycle's median and min-max over them "
                        f"(default: {DEFAULT_SEEDS} with the fee-env plant, 1 with --plant mpm)")
    p.add_argument("--no-planner", action="store_true",
                   help="dig the Bezier path every cycle (calibration and prediction only)")
    p.add_argument("--window", type=int, default=None,
                   help="calibrate on the last WINDOW cycles together (default: "
                        "wheelloader.adaptation.DEFAULT_WINDOW)")
    p.add_argument("--prior", choices=("none", "nominal"), default=None,  # wheelloader.adaptation.PRIOR_NAMES
                   help="the calibration's prior: 'nominal' holds gamma, K and n softly at the nominal soil (the "
                        "'sand' preset; one cycle cannot identify them) and fits cohesion, adhesion, phi and delta; "
                        f"'none' fits all freely (default: {DEMO_PRIOR})")
    p.add_argument("--mpc", action="store_true",
                   help="execute each plan with the receding-horizon MPC instead of tracking it (slower)")
    p.add_argument("--plant", choices=DEMO_PLANTS, default="fee-env",
                   help="where the cycles are dug: the FEE env (default, seconds) or the MPM continuum reference "
                        "(needs the mpm extra; about 3 minutes per cycle at 2 cm, 2 x CYCLES cycles; resumable)")
    p.add_argument("--resolution", type=float, default=None,
                   help="MPM grid spacing [m], 0.005-0.1, with --plant mpm only (default: 0.02, the verified one)")
    p.add_argument("--compiled", action="store_true",
                   help="compile the planner's derivatives to C once per machine, cached with the NLP cache "
                        "(minutes of CPU the first time; the same table; needs a C compiler, else CasADi's virtual "
                        "machine with a warning); later runs, with or without this flag, use that library")
    p.add_argument("--jobs", type=int, default=None,
                   help="run the seeds side by side in this many threads (the same table and output; default: one "
                        "per seed, at most two per CPU, 1 on one CPU; with the fee-env plant and the planner, "
                        "without --mpc)")
    add_force_flag(p)
    p.set_defaults(func=run)


def _one_malloc_arena() -> None:
    """Ask glibc's malloc for one arena: by default each thread that allocates while another does gets its own, and
    the seeds side by side (``--jobs``) then held about 20 MB more at the peak (measured with 3 seeds: 285 against
    265 MB, the same CPU time). Elsewhere (no ``mallopt``) nothing changes."""
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return
    m_arena_max = -8  # glibc's M_ARENA_MAX
    mallopt(ctypes.c_int(m_arena_max), ctypes.c_int(1))


def run(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader demo``."""
    from wheelloader.demo import DEFAULT_SEEDS, MAX_SEEDS, run_demo
    from wheelloader.estimator import ParameterError

    if args.cycles < 1 or args.cycles > 50:
        raise ParameterError(f"--cycles must be between 1 and 50, got {args.cycles}")
    if not 0 <= args.seed < 2**32:
        raise ParameterError(f"--seed must be between 0 and 2^32 - 1, got {args.seed}")
    seeds = args.seeds if args.seeds is not None else DEFAULT_SEEDS if args.plant == "fee-env" else 1
    if not 1 <= seeds <= MAX_SEEDS:
        raise ParameterError(f"--seeds must be between 1 and {MAX_SEEDS}, got {seeds}")
    if args.seed + seeds > 2**32:
        raise ParameterError(f"--seed + --seeds must stay below 2^32, got {args.seed} + {seeds}")
    if args.resolution is not None and args.plant != "mpm":
        raise ParameterError("--resolution sets the MPM grid and needs --plant mpm")
    resolution = 0.02 if args.resolution is None else args.resolution
    if not (math.isfinite(resolution) and 0.005 <= resolution <= 0.1):
        raise ParameterError(f"--resolution must be between 0.005 and 0.1 m, got {args.resolution}")
    if args.window is not None and args.window < 1:
        raise ParameterError(f"--window must be a positive number of cycles, got {args.window}")
    if args.jobs is not None and not 1 <= args.jobs <= MAX_SEEDS:
        raise ParameterError(f"--jobs must be between 1 and {MAX_SEEDS}, got {args.jobs}")
    if args.jobs is not None and args.jobs > 1 and (args.plant != "fee-env" or args.mpc or args.no_planner):
        raise ParameterError("--jobs above 1 needs the fee-env plant with the planner and without --mpc")
    if args.mpc and args.plant != "fee-env":
        raise ParameterError("--mpc needs the env's feedback and runs only with the fee-env plant")
    if args.plant == "mpm":
        try:
            import taichi  # noqa: F401
        except ImportError:
            raise ParameterError("--plant mpm needs the mpm extra (Taichi): pip install 'wheelloader[mpm]'") from None
    _one_malloc_arena()
    run = OutputRun(force=args.force)
    out = run.directory("-o/--out", args.out, fresh=not args.force)
    with run:
        staged = run.staged(out)
        if args.plant == "mpm" and (out / "cycles").is_dir():  # resume the cycles an earlier run saved
            shutil.copytree(out / "cycles", staged / "cycles", dirs_exist_ok=True)
        summary = run_demo(staged, cycles=args.cycles, seed=args.seed, use_planner=not args.no_planner,
                           progress=lambda line: print(line, flush=True), mpc=args.mpc, plant=args.plant,
                           prior=args.prior, resolution=resolution, window=args.window, seeds=seeds,
                           compiled=args.compiled, jobs=args.jobs)
    print()
    print(summary["table"])
    print()
    for name in ("summary.json", summary["table_markdown"], *summary["figures"]):
        print(f"wrote {out / name}")
    print(f"results written to {out.resolve()}")
    return 0
