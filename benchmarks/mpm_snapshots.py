"""Figure of one MPM cycle: the soil and the bucket at a few instants, forces and fill over time.

``python benchmarks/mpm_snapshots.py --out docs/mpm_cycle.png [--soil gravel --path 1 --resolution 0.02]``
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="docs/mpm_cycle.png", help="PNG to write (a JSON of the figures beside it)")
    parser.add_argument("--soil", default="gravel")
    parser.add_argument("--path", type=int, default=1, choices=(1, 2, 3, 4), help="paper_paths() index, 1-based")
    parser.add_argument("--resolution", type=float, default=0.02)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--times", type=float, nargs="*", default=[0.0, 1.5, 2.5, 3.5, 4.67])
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wheelloader.estimator import Pile, paper_paths
    from wheelloader.provenance import machine_info
    from wheelloader.references.mpm import MPMPlant

    path = paper_paths()[args.path - 1]
    pile = Pile.trapezoid()
    plant = MPMPlant(args.resolution, threads=args.threads)
    wanted = sorted({min(max(w, float(path.t[0])), float(path.t[-1])) for w in args.times})
    shots: dict[float, np.ndarray] = {}

    def observer(t: float, positions: np.ndarray) -> None:
        for w in wanted:
            if w not in shots and t >= w - 1e-9:
                shots[w] = positions.copy()

    log = plant.dig(path, pile, args.soil, seed=args.seed, observer=observer)
    fig = plt.figure(figsize=(13, 8))
    grid = fig.add_gridspec(2, len(shots))
    for j, (w, pos) in enumerate(sorted(shots.items())):
        ax = fig.add_subplot(grid[0, j])
        k = int(np.argmin(np.abs(log.path.t - w)))
        pose = (log.path.x[k], log.path.z[k], log.path.blade_angle[k])
        inside = plant.shape.inside(pose, pos)
        ax.scatter(pos[~inside, 0], pos[~inside, 1], s=0.2, c="tan", rasterized=True)
        ax.scatter(pos[inside, 0], pos[inside, 1], s=0.2, c="sienna", rasterized=True)
        for plate in plant.shape.plates:
            pts = plant.shape.world_points(pose, np.array([plate.start, plate.end]))
            ax.plot(pts[:, 0], pts[:, 1], "k-", lw=2)
        ax.plot(pile.x, pile.heights, "k:", lw=0.6)
        ax.plot(log.path.x, log.path.z, "b:", lw=0.6)
        ax.set(xlim=(-0.7, 2.1), ylim=(-0.25, 1.7), aspect="equal", title=f"t = {log.path.t[k]:.2f} s")
        ax.tick_params(labelsize=7)
    ax = fig.add_subplot(grid[1, : max(1, len(shots) // 2 + 1)])
    ax.plot(log.path.t, log.tangential, lw=0.8, label="F_T")
    ax.plot(log.path.t, log.normal, lw=0.8, label="F_N")
    ax.set(xlabel="t [s]", ylabel="force [N] (1 m bucket)", title=f"{args.soil}, {path.name}, dx {args.resolution:g} m")
    ax.legend()
    ax = fig.add_subplot(grid[1, max(1, len(shots) // 2 + 1):])
    ax.plot(log.path.t, log.fill_volume, "k-")
    ax.axhline(plant.bucket.capacity, color="0.6", ls="--", label="Bucket.capacity")
    ax.set(xlabel="t [s]", ylabel="fill inside the outline [m^3]")
    ax.legend()
    fig.tight_layout()
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    command = " ".join(["python benchmarks/mpm_snapshots.py", *(sys.argv[1:] if argv is None else argv)])
    summary = {"command": command, "wall_s": log.metadata["wall_s"],
               "particles": log.metadata["particles"], "max_F_T": float(np.max(log.tangential)),
               "max_F_N": float(np.max(log.normal)), "fill_end": float(log.fill_volume[-1]),
               "mass_balance": log.metadata["mass_balance"], "machine": machine_info()}
    out.with_suffix(".json").write_text(json.dumps(summary, indent=1))
    print(json.dumps({k: v for k, v in summary.items() if k != "machine"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
