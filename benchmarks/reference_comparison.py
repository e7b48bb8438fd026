"""The paper's experiments on every reference side by side: the paper's figures (Algoryx), the MPM continuum, the DEM.

Reads the ``results.json`` that ``benchmarks/paper_experiments.py`` wrote for each reference set and writes
one Markdown table (F_R RMSE, filtered, in % of the mean observed |F_R|; ours and the paper's
multi-stage method per reference). Nothing is recomputed here: the figures are those of the runs named
in the table's footnote.

Run: ``python benchmarks/reference_comparison.py --mpm docs/results/paper_mpm --dem docs/results/paper_dem
--out docs/results/references.md``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from wheelloader.provenance import commit_label

#: The paper's own figures against Algoryx (Tables 3-4, Figs 8-9), for the rows where it gives one.
PAPER = {
    "training": "8.6 %",
    "path2": "11.2–15.5 %", "path3": "11.2–15.5 %", "path4": "11.2–15.5 %",
    "dual": "17.3 %",
    "gravel": "9.0 %", "modified_sand": "8.6 %", "dirt": "15.3 %", "sand": "–",
}


def rows_of(results: dict) -> dict[str, dict[str, float]]:
    """Case -> {method: filtered F_R RMSE [%]} of one paper_experiments results.json."""
    out: dict[str, dict[str, float]] = {}
    methods = list(results["table3"])
    out["training"] = {m: results["table3"][m]["train"]["filtered"][1] for m in methods}
    for k in ("path2", "path3", "path4"):
        if k in results["fig8"][methods[0]]:
            out[k] = {m: results["fig8"][m][k]["filtered"][1] for m in methods}
    if "fig9" in results:
        out["dual"] = {m: results["fig9"][m]["cycle2_carved_surface"]["filtered"][1] for m in methods}
    for soil, r in results["table4"].items():
        out[soil] = {m: r[m]["rmse"]["filtered"][1] for m in methods}
    out["time"] = {m: results["table3"][m]["time_s"] for m in methods}
    return out


LABELS = {
    "training": "Table 3: gravel path 1 (training)",
    "path2": "Fig. 8: gravel path 2 (unseen)", "path3": "Fig. 8: gravel path 3 (unseen)",
    "path4": "Fig. 8: gravel path 4 (unseen)",
    "dual": "Fig. 9: dual cycle 2 (carved surface)",
    "gravel": "Table 4: gravel path 1", "modified_sand": "Table 4: modified sand path 1",
    "dirt": "Table 4: dirt path 1", "sand": "Table 4: sand path 1",
}


def table(refs: dict[str, dict]) -> str:
    """Markdown: one row per case, per reference ours / multi-stage."""
    parsed = {name: rows_of(res) for name, res in refs.items()}
    head = "| case | paper (Algoryx) | " + " | ".join(f"{n}: ours / multi-stage" for n in refs) + " |"
    lines = [head, "|---|---|" + "---|" * len(refs)]
    for key, label in LABELS.items():
        if not any(key in p for p in parsed.values()):
            continue
        cells = []
        for p in parsed.values():
            r = p.get(key)
            cells.append("–" if r is None else f"{r['default']:.1f} / {r['multi-stage']:.1f} %")
        lines.append(f"| {label} | {PAPER[key]} | " + " | ".join(cells) + " |")
    cells = [f"{p['time']['default']:.2f} / {p['time']['multi-stage']:.2f} s" for p in parsed.values()]
    lines.append("| calibration time, gravel path 1 | 47.0 s (multi-stage) | " + " | ".join(cells) + " |")
    runs = "; ".join(f"{n}: `python benchmarks/paper_experiments.py --data {res['settings']['data']}` at "
                     f"{commit_label(res['machine'])}" for n, res in refs.items())
    lines += ["", f"*F_R RMSE against the reference filtered with a Gaussian of σ = 0.1 s, in % of the mean observed "
              f"|F_R| over the in-soil samples (unfiltered figures in each run's report). {runs}; table by "
              "`python benchmarks/reference_comparison.py`.*"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mpm", default="docs/results/paper_mpm", help="paper_experiments output on the MPM set")
    parser.add_argument("--dem", default="docs/results/paper_dem", help="paper_experiments output on the DEM set")
    parser.add_argument("--out", default="docs/results/references.md", help="Markdown table to write")
    args = parser.parse_args(argv)
    refs = {}
    for name, folder in (("MPM continuum", args.mpm), ("Yade DEM", args.dem)):
        path = Path(folder) / "results.json"
        if not path.is_file():
            parser.error(f"{path} not found: run benchmarks/paper_experiments.py with --out {folder} first")
        refs[name] = json.loads(path.read_text())
    text = table(refs)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
