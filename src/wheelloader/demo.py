"""``wheelloader demo``: the cycle-to-cycle adaptation loop on the built-in default.

The plant is the default pile with a hidden gravel-like soil and sensor
noise. Cycle 1 digs the default Bezier path with nominal parameters; after
each cycle the soil is calibrated (default method, warm-started), the next
cycle's forces are predicted, the next path is planned on the carved pile,
and it is dug. The fixed-path baseline runs beside it for comparison. The
demo prints a per-cycle table and writes figures and a JSON summary.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

DEFAULT_CYCLES = 5


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    p = subparsers.add_parser("demo", help="run the cycle-to-cycle adaptation demo on the built-in default",
                              description=__doc__.splitlines()[0])
    p.add_argument("-o", "--out", default="wheelloader-demo",
                   help="output directory (a new NAME-2, NAME-3 ... is used if it exists; default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="write into --out even if it holds earlier results")
    p.add_argument("--cycles", type=int, default=DEFAULT_CYCLES, help="digging cycles (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the plant (default: %(default)s)")
    p.add_argument("--no-planner", action="store_true",
                   help="dig the Bezier path every cycle (calibration and prediction only)")
    p.add_argument("--mpc", action="store_true",
                   help="execute each plan with the receding-horizon MPC instead of tracking it (slower)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader demo``."""
    from wheelloader.estimator.errors import ParameterError
    from wheelloader.outdir import fresh_directory

    if args.cycles < 1 or args.cycles > 50:
        raise ParameterError(f"--cycles must be between 1 and 50, got {args.cycles}")
    out = fresh_directory(args.out, args.overwrite)
    summary = run_demo(out, cycles=args.cycles, seed=args.seed, use_planner=not args.no_planner,
                       progress=lambda line: print(line, flush=True), mpc=args.mpc)
    print()
    print(summary["table"])
    print()
    print(f"results written to {out.resolve()}")
    return 0


def run_demo(out: Path, cycles: int = DEFAULT_CYCLES, seed: int = 0, use_planner: bool = True,
             progress: Any = None, mpc: bool = False) -> dict[str, Any]:
    """Run the loop (ours and the fixed baseline), write figures and ``summary.json`` into ``out``."""
    import gymnasium as gym

    import wheelloader.envs  # noqa: F401  (registers the env ids)
    from wheelloader.adaptation import (
        LOOP_ENV_KWARGS,
        NOMINAL_SOIL,
        Calibrating,
        FixedBezier,
        default_planner,
        format_table,
        hidden_default_soil,
        run_loop,
    )
    from wheelloader.estimator import preset

    say = progress or (lambda line: None)
    start = time.perf_counter()
    hidden = hidden_default_soil()
    if use_planner:
        say("building the planner's CasADi NLPs (once, ~10 s) ...")
    planner = default_planner(mpc=mpc) if use_planner else None
    results = {}
    for strategy in (Calibrating(preset(NOMINAL_SOIL), planner=planner), FixedBezier(preset(NOMINAL_SOIL))):
        say(f"running {cycles} cycles, strategy '{strategy.name}' ...")
        env = gym.make("wheelloader/BucketLoading-v0", soil=hidden, **LOOP_ENV_KWARGS)
        records, logs = run_loop(env, strategy, cycles=cycles, seed=seed, progress=say)
        results[strategy.name] = (records, logs)
        env.close()
    files = write_figures(out, results)
    ours = results["ours"][0]
    table = format_table(ours + results["fixed"][0])
    summary = {
        "plant": {"soil": hidden.to_dict(), "sensor_noise_N": 150.0, "pile": "trapezoid 30 deg, 1 m high"},
        "nominal_soil": NOMINAL_SOIL,
        "planner": ("none (Bezier path every cycle)" if planner is None
                    else "CasADi plan + MPC" if mpc else "CasADi plan, tracked"),
        "cycles": {name: [r.to_dict() for r in recs] for name, (recs, _) in results.items()},
        "final_parameters_ours": ours[-1].params,
        "wall_time_s": time.perf_counter() - start,
        "figures": files,
        "table": table,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary


def write_figures(out: Path, results: dict[str, Any]) -> list[str]:
    """Observed vs predicted forces, piles and paths, metrics over cycles."""
    import numpy as np

    from wheelloader import figures
    from wheelloader.estimator import predict, preset

    records, logs = results["ours"]
    n = len(logs)
    fig, axes = figures.new_figure(1, n, (3.2 * n, 3.2))
    axes = np.atleast_1d(axes)
    for k, (ax, log, rec) in enumerate(zip(axes, logs, records, strict=True)):
        pred = predict(preset(rec.params) if isinstance(rec.params, str) else _soil(rec.params), log)
        figures.plot_forces(log.path.t, {"measured F_R": log.resultant, "predicted F_R": pred.forces.resultant},
                            ax=ax, styles={"measured F_R": "-", "predicted F_R": "--"})
        ax.set_title(f"cycle {k + 1}: RMSE {rec.prediction_rmse_percent:.1f} %", fontsize=9)
    figures.save(fig, out / "forces.png")

    fig, ax = figures.new_figure(1, 1, (8, 4))
    paths = [log.path.shifted(name=f"cycle {k + 1}") for k, log in enumerate(logs)]
    figures.plot_pile_and_paths(logs[0].pile, paths, ax=ax,
                                carved=[log.pile_after for log in logs], x_range=(-0.5, 3.5))
    ax.set_title("pile, paths and the soil each cycle removed ('ours')")
    figures.save(fig, out / "piles.png")

    fig, axes = figures.new_figure(1, 4, (15, 3.4))
    for name, (recs, _) in results.items():
        c = [r.cycle for r in recs]
        axes[0].plot(c, [r.prediction_rmse_percent for r in recs], "o-", label=name)
        axes[1].plot(c, [100 * r.fill_fraction for r in recs], "o-", label=name)
        axes[2].plot(c, [r.energy_per_m3 / 1e3 for r in recs], "o-", label=name)
        axes[3].plot(c, [r.between_cycles_s for r in recs], "o-", label=name)
    for ax, label in zip(axes, ("prediction F_R RMSE [%]", "bucket fill [%]", "energy per m^3 [kJ/m^3]",
                                "calibration + planning [s]"), strict=True):
        ax.set_xlabel("cycle")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    figures.save(fig, out / "metrics.png")
    return ["forces.png", "piles.png", "metrics.png"]


def _soil(params: dict[str, float]):
    from wheelloader.estimator import SoilParams

    return SoilParams.from_dict(params)
