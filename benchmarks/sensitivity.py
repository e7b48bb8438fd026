"""Which soil parameters can one cycle, and several, pin down? Sobol indices of the predicted F_R per path family.

For each path family of the project's continuum data, the aggregated Sobol indices
(:func:`wheelloader.estimator.calibration.sensitivity.sobol_indices`: SALib; the output is log F_R at the
in-soil samples, variance-weighted) of the force model along one cycle of the family, over the plausible box
:data:`~wheelloader.estimator.calibration.sensitivity.SOBOL_RANGES`:

* ``data/mpm``'s four smooth paths on the trapezoid pile (gravel; the depth and the carving are the path's, the
  soil does not enter the indices) and the 25 deg pile's path (the transfer benchmark's test families);
* the saved MPM loops' families (``data/results/adaptation_mpm*``: the strategies ``fixed``, ``oracle``,
  ``ours``, ``paper`` of the base, ``curlout`` and ``end55`` runs; their first gravel cycle, seed 0, and their
  third, dug on a carved pile): the training and validation families.

Several cycles: the indices of two paths' outputs joined (each path weighing the same): neighbouring
``data/mpm`` paths, and two consecutive cycles of a loop.

The rule (written to ``sensitivity.json`` as ``free_one``/``free_several``, used by ``benchmarks/transfer.py``):
a parameter is fitted when its total index reaches :data:`THRESHOLD` in the median over the TRAINING families
(the loops' base and ``curlout`` runs; the test and validation families are reported, not used); the others are
held at a prior. In soil the ``fee`` and ``fee-payload`` models are the same FEE on the carved fill, so one set of
indices serves both.

Run: ``python benchmarks/sensitivity.py --out docs/results/sensitivity`` (about a minute; needs the ``model``
extra, SALib; writes ``sensitivity.json``, ``table.md`` and ``sensitivity.png``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from wheelloader.estimator import CycleLog
from wheelloader.estimator.calibration.options import CalibrationOptions
from wheelloader.estimator.calibration.sensitivity import SOBOL_RANGES, sobol_indices
from wheelloader.estimator.force_models import cycle_contact_state
from wheelloader.estimator.soil_vector import SOIL_VECTOR_NAMES
from wheelloader.provenance import machine_info

#: Total index a parameter needs (median over the training families) to be fitted.
THRESHOLD = 0.05
BASE = 256
POINTS = 40
STRATEGIES = ("fixed", "oracle", "ours", "paper")
RUNS = {"adaptation_mpm": "train", "adaptation_mpm_curlout": "train", "adaptation_mpm_end55": "validation"}


def families(data: Path, results: Path) -> list[dict]:
    """``[{name, split, paths}]``: one or two cycles per family (module docstring)."""
    out = [{"name": f"data/mpm path {i}", "split": "test", "paths": [data / f"gravel_path{i}.csv"]}
           for i in range(1, 5)]
    out.append({"name": "data/mpm 25 deg pile", "split": "test", "paths": [data / "gravel_slope25_path1.csv"]})
    for run, split in RUNS.items():
        for strategy in STRATEGIES:
            folder = results / run / "cycles" / "gravel" / "seed0" / strategy
            for k in (1, 3):
                out.append({"name": f"{run.removeprefix('adaptation_')} {strategy} cycle {k}", "split": split,
                            "paths": [folder / f"cycle{k}.csv.xz"]})
    pairs = [{"name": f"data/mpm paths {i}+{i + 1}", "split": "test",
              "paths": [data / f"gravel_path{i}.csv", data / f"gravel_path{i + 1}.csv"]} for i in range(1, 4)]
    for run, split in RUNS.items():
        for strategy in STRATEGIES:
            folder = results / run / "cycles" / "gravel" / "seed0" / strategy
            pairs.append({"name": f"{run.removeprefix('adaptation_')} {strategy} cycles 1+2", "split": split,
                          "paths": [folder / "cycle1.csv.xz", folder / "cycle2.csv.xz"]})
    for p in out + pairs:
        p["cycles"] = len(p["paths"])
    return out + pairs


def rule(rows: list[dict], cycles: int) -> dict:
    """Median total index over the training families of ``cycles`` cycles, and the parameters it frees."""
    train = [r for r in rows if r["split"] == "train" and r["cycles"] == cycles]
    median = {n: float(np.median([r["total"][n] for r in train])) for n in SOIL_VECTOR_NAMES}
    return {"families": len(train), "median_total": median,
            "free": [n for n in SOIL_VECTOR_NAMES if median[n] >= THRESHOLD]}


def run(data: Path, results: Path, base: int = BASE) -> dict:
    opts = CalibrationOptions(force_model="fee-payload")
    rows = []
    for fam in families(data, results):
        logs = [CycleLog.load(p) for p in fam["paths"]]
        states = [cycle_contact_state(log, opts.force_model, opts.payload, opts.slope_window, opts.fill)
                  for log in logs]
        res = sobol_indices(states, logs[0].bucket, opts.model_options, base=base, points=POINTS)
        rows.append({"family": fam["name"], "split": fam["split"], "cycles": fam["cycles"],
                     "paths": [str(p) for p in fam["paths"]],
                     "max_depth_m": float(max(np.max(s.depth) for s in states)), **res.to_dict()})
        print(f"{fam['name']}: " + ", ".join(f"{n} {v:.2f}" for n, v in res.total.items()), flush=True)
    one, several = rule(rows, 1), rule(rows, 2)
    return {"benchmark": "sensitivity", "ranges": {k: list(v) for k, v in SOBOL_RANGES.items()},
            "output": "log F_R at the in-soil samples, variance-weighted", "base": base, "points": POINTS,
            "threshold": THRESHOLD, "one_cycle": one, "several_cycles": several, "free_one": one["free"],
            "free_several": sorted(set(one["free"]) | set(several["free"]), key=SOIL_VECTOR_NAMES.index),
            "families": rows, "machine": machine_info()}


def table(result: dict) -> str:
    names = SOIL_VECTOR_NAMES
    lines = ["| family | split | cycles | max depth | " + " | ".join(f"S_T {n} (S_1)" for n in names) + " |",
             "|---|---|---|---|" + "---|" * len(names)]
    for r in result["families"]:
        cells = " | ".join(f"{r['total'][n]:.2f} ({r['first'][n]:.2f})" for n in names)
        lines.append(f"| {r['family']} | {r['split']} | {r['cycles']} | {r['max_depth_m']:.2f} m | {cells} |")
    for key, label in (("one_cycle", "one cycle"), ("several_cycles", "two cycles")):
        med = result[key]["median_total"]
        lines.append(f"| **median, training, {label}** | train | | | "
                     + " | ".join(f"**{med[n]:.2f}**" for n in names) + " |")
    lines.append("")
    lines.append(f"Fitted from one cycle (median S_T >= {result['threshold']}): {', '.join(result['free_one'])}; "
                 f"from two or more: {', '.join(result['free_several'])}; held at the training prior: "
                 f"{', '.join(n for n in names if n not in result['free_one'])}.")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in result["families"] if r["cycles"] == 1]
    names = SOIL_VECTOR_NAMES
    fig, ax = plt.subplots(figsize=(12, 5))
    width = 0.8 / len(names)
    for k, n in enumerate(names):
        ax.bar(np.arange(len(rows)) + k * width, [r["total"][n] for r in rows], width, label=n)
    ax.axhline(result["threshold"], color="k", ls="--", lw=1)
    ax.set_xticks(np.arange(len(rows)) + 0.4 - width / 2, [r["family"] for r in rows], rotation=70, fontsize=7)
    ax.set_ylabel("total Sobol index of log F_R (in soil)")
    ax.set_title(f"Which parameters a cycle pins down (dashed: threshold {result['threshold']})")
    ax.legend(fontsize=8, ncol=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/mpm"), help="folder of data/mpm's cycles")
    parser.add_argument("--results", type=Path, default=Path("data/results"), help="folder of the saved loops")
    parser.add_argument("--base", type=int, default=BASE, help="SALib base sample count (power of 2)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    args = parser.parse_args()
    result = run(args.data, args.results, args.base)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "sensitivity.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "table.md").write_text(table(result))
    plot(result, args.out / "sensitivity.png")
    print(table(result), end="")


if __name__ == "__main__":
    main()
