"""``wheelloader demo``: the main job on the built-in default.

Predicts the forces of the default digging path on the default pile with the
default soil and writes a figure and a JSON summary into an output directory.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

DEFAULT_SOIL = "gravel"


def register(subparsers: Any) -> None:
    """Add the ``demo`` subcommand."""
    p = subparsers.add_parser("demo", help="run the built-in demo on the default pile and soil",
                              description=__doc__.splitlines()[0])
    p.add_argument("-o", "--out", default="wheelloader-demo",
                   help="output directory (a new NAME-2, NAME-3 ... is used if it exists; default: %(default)s)")
    p.add_argument("--overwrite", action="store_true", help="write into --out even if it holds earlier results")
    p.add_argument("--soil", default=DEFAULT_SOIL, help="soil preset (default: %(default)s)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Handler of ``wheelloader demo``."""
    from wheelloader.outdir import fresh_directory

    out = fresh_directory(args.out, args.overwrite)
    summary = predict_default(out, args.soil)
    print(f"peak F_R {summary['peak_resultant_N'] / 1e3:.2f} kN, bucket fill {summary['fill_fraction']:.0%}")
    print(f"results written to {out.resolve()}")
    return 0


def predict_default(out: Path, soil_name: str = DEFAULT_SOIL) -> dict[str, Any]:
    """Predict and plot the default path's forces; write ``forces.png`` and ``summary.json`` into ``out``."""
    from wheelloader import figures
    from wheelloader.estimator import Bucket, Pile, contact_state, default_path, preset, soil_forces

    soil, bucket, pile, path = preset(soil_name), Bucket(), Pile.trapezoid(), default_path()
    start = time.perf_counter()
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    forces = soil_forces(soil, state, bucket)
    elapsed = time.perf_counter() - start
    fig, (ax_path, ax_force) = figures.new_figure()
    figures.plot_pile_and_paths(pile, [path], ax=ax_path, carved=[state.carve.pile], x_range=(-0.5, 2.5))
    ax_path.set_title("default pile, path and carved surface")
    figures.plot_forces(path.t, {"F_T": forces.tangential, "F_N": forces.normal, "F_R": forces.resultant},
                        ax=ax_force)
    ax_force.set_title(f"predicted forces, soil '{soil_name}'")
    figures.save(fig, out / "forces.png")
    summary = {
        "soil": soil_name,
        "soil_parameters": soil.to_dict(),
        "samples": len(path),
        "peak_resultant_N": float(forces.resultant.max()),
        "mean_resultant_N": float(forces.resultant.mean()),
        "fill_m3": float(state.carve.in_bucket),
        "fill_fraction": float(state.carve.in_bucket / bucket.capacity),
        "samples_outside_validity_domain": forces.flag_summary(),
        "prediction_time_s": elapsed,
        "figures": ["forces.png"],
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    return summary
