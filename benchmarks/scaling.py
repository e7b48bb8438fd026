"""Scaling out on this machine: the sweep runner with 1 and 2 workers, and RLlib env-steps/s with 1 and 2 env runners.

One run measures, one after the other on the same machine (compare the ratios, not the absolute times,
on a shared machine; the load average before and after each step is recorded):

1. the adaptation benchmark (``benchmarks/adaptation.py``) in one configuration (default ``--seeds 1``: 3
   soils x 2 piles x 1 seed x 4 strategies = 24 loops of 5 cycles) in three modes: ``--ray off`` (serial),
   ``--ray local --ray-cpus 1`` (one Ray worker: Ray's own cost) and ``--ray local --ray-cpus 2`` (two
   workers), ``--repeats`` times in alternating order (a drifting load favours no mode); each as its own
   process, timed from the command's start (Ray's start-up included) and by the sweep itself; the three
   tables are checked to be equal apart from wall-clock columns;
2. ``train/rllib_speed.py --runners 1 2 2 1``: RLlib PPO env-steps/s with 1 and 2 env runners, twice each
   in alternating order (skipped with a note when the rllib extra is not installed).

Writes ``scaling.json`` (every figure, machine, versions, commit, loads) and ``scaling.md`` (the README's
table) into ``--out``.

Usage::

    python benchmarks/scaling.py --out docs/results/scaling
    python benchmarks/scaling.py --seeds 3 --out results/scaling       # the full adaptation benchmark
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from wheelloader.provenance import commit_label, machine_info

ROOT = Path(__file__).resolve().parents[1]
#: Wall-clock fields of an adaptation row (differ between runs); every other field must be equal.
TIMES = ("calibration_s", "planning_s", "between_cycles_s")
#: (label, --ray arguments, workers) of the three sweep runs.
MODES = (("serial (--ray off)", ["--ray", "off"], 1),
         ("Ray, 1 worker (--ray local --ray-cpus 1)", ["--ray", "local", "--ray-cpus", "1"], 1),
         ("Ray, 2 workers (--ray local --ray-cpus 2)", ["--ray", "local", "--ray-cpus", "2"], 2))


def _load() -> list[float] | None:
    return machine_info()["loadavg_1_5_15min"]


def _run(cmd: list[str], log: Path) -> float:
    """Run ``cmd`` (output to ``log``), return its wall time [s]; a failure stops the benchmark."""
    start = time.perf_counter()
    with open(log, "w") as fh:
        proc = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=ROOT)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed (exit {proc.returncode}); see {log}")
    return wall


def _comparable(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: v for k, v in r.items() if k not in TIMES} for r in rows]


def sweep_runs(seeds: int, cycles: int, repeats: int, work: Path) -> dict[str, Any]:
    """The adaptation benchmark in the three modes, ``repeats`` times, the order reversed every other time
    (off, 1, 2, 2, 1, off, ...) so that a drifting machine load favours no mode."""
    runs, reference = [], None
    order = [mode for k in range(repeats) for mode in (MODES if k % 2 == 0 else MODES[::-1])]
    for label, ray_args, workers in order:
        out = work / f"adaptation_{len(runs)}"
        cmd = [sys.executable, "benchmarks/adaptation.py", "--seeds", str(seeds), "--cycles", str(cycles),
               "--out", str(out), *ray_args]
        load0 = _load()
        wall = _run(cmd, work / f"adaptation_{len(runs)}.log")
        result = json.loads((out / "adaptation.json").read_text())
        rows = _comparable(result["rows"])
        reference = rows if reference is None else reference
        runs.append({"label": label, "command": " ".join(cmd[1:-2 - len(ray_args)] + ray_args), "workers": workers,
                     "process_wall_s": wall, "sweep_wall_s": result["sweep"]["wall_s"],
                     "unit_seconds_total": result["sweep"]["unit_seconds_total"], "units": result["sweep"]["units"],
                     "same_table_as_serial": rows == reference,
                     "between_cycles_median_s": {k: v["between_cycles_median_s"] for k, v in result["summary"].items()},
                     "loadavg_before": load0, "loadavg_after": _load()})
        print(f"{label}: {wall:.0f} s (sweep {result['sweep']['wall_s']:.0f} s), same table: "
              f"{runs[-1]['same_table_as_serial']}", flush=True)
    modes = []
    for label, _, workers in MODES:
        mine = [r for r in runs if r["label"] == label]
        modes.append({"label": label, "workers": workers,
                      "process_wall_s": [r["process_wall_s"] for r in mine],
                      "sweep_wall_s": [r["sweep_wall_s"] for r in mine],
                      "median_process_wall_s": statistics.median(r["process_wall_s"] for r in mine),
                      "same_table_as_serial": all(r["same_table_as_serial"] for r in mine)})
    base = modes[0]["median_process_wall_s"]
    for mode in modes:
        mode["speed_up_vs_serial"] = base / mode["median_process_wall_s"]
    return {"setup": {"seeds": seeds, "cycles": cycles, "loops": runs[0]["units"], "repeats": repeats},
            "runs": runs, "modes": modes}


def rllib_runs(iterations: int, work: Path) -> dict[str, Any]:
    """``train/rllib_speed.py --runners 1 2`` (skipped without the rllib extra)."""
    if importlib.util.find_spec("ray") is None or importlib.util.find_spec("torch") is None:
        return {"skipped": "RLlib not installed: pip install torch==2.13.0 && pip install -e \".[rllib]\""}
    cmd = [sys.executable, "train/rllib_speed.py", "--runners", "1", "2", "2", "1", "--iterations", str(iterations),
           "--out", str(work / "rllib")]
    wall = _run(cmd, work / "rllib.log")
    report = json.loads((work / "rllib" / "rllib_speed.json").read_text())
    keep = ("num_env_runners", "num_envs_per_env_runner", "vectorize_mode", "build_s", "timed_env_steps",
            "timed_wall_s", "env_steps_per_s", "sampling_env_steps_per_s", "learner_share", "iteration_s_median",
            "loadavg_before", "loadavg_after")
    return {"command": " ".join(cmd[1:-2]), "process_wall_s": wall, "settings": report["settings"],
            "runs": [{k: r[k] for k in keep} for r in report["runs"]]}


def markdown(result: dict[str, Any]) -> str:
    """The README table of a result."""
    sweep = result["sweep"]
    s = sweep["setup"]
    lines = [f"| adaptation sweep ({s['loops']} loops of {s['cycles']} cycles) | workers | wall time per run "
             f"({s['repeats']} runs, median) | speed-up vs serial (medians) | same table as serial |",
             "|---|---|---|---|---|"]
    for m in sweep["modes"]:
        times = " / ".join(f"{t:.0f}" for t in m["process_wall_s"])
        lines.append(f"| {m['label']} | {m['workers']} | {times} s ({m['median_process_wall_s']:.0f} s) | "
                     f"{m['speed_up_vs_serial']:.2f}x | {'yes' if m['same_table_as_serial'] else '**no**'} |")
    rl = result["rllib"]
    lines += [""]
    if "skipped" in rl:
        lines.append(f"RLlib: {rl['skipped']}.")
    else:
        lines += ["| RLlib PPO (batched env by id, vector_entry_point) | env runners x envs | env-steps/s end to end | "
                  "sampling env-steps/s | learner share of an iteration |", "|---|---|---|---|---|"]
        base = statistics.median(r["env_steps_per_s"] for r in rl["runs"] if r["num_env_runners"] == 1)
        for r in rl["runs"]:
            lines.append(f"| {r['timed_env_steps']} env-steps after a warm-up iteration | {r['num_env_runners']} x "
                         f"{r['num_envs_per_env_runner']} | {r['env_steps_per_s']:.0f} "
                         f"({r['env_steps_per_s'] / base:.2f}x) | {r['sampling_env_steps_per_s']:.0f} | "
                         f"{r['learner_share']:.0%} |")
    m = result["machine"]
    loads = [r["loadavg_before"][0] for r in sweep["runs"] if r["loadavg_before"]]
    loads += [r["loadavg_before"][0] for r in rl.get("runs", []) if r["loadavg_before"]]
    last = (rl.get("runs") or sweep["runs"])[-1]["loadavg_after"]
    spread = ", ".join(f"{v:.1f}" for v in loads) + (f", {last[0]:.1f}" if last else "")
    lines += ["", f"*`python benchmarks/scaling.py --seeds {s['seeds']} --cycles {s['cycles']} --repeats "
              f"{s['repeats']}` at commit {commit_label(m)}; {m.get('cpu_count')} cores ({m.get('cpu') or 'CPU'}) "
              f"shared with other jobs: 1-min load average before each run (sweeps in run order, then RLlib) and "
              f"at the end: {spread}. The runs alternate (serial, 1, 2 workers, then the reverse) in one invocation; "
              "compare the ratios. The tables agree in every column but the wall-clock ones.*"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/scaling", help="output directory")
    parser.add_argument("--seeds", type=int, default=1, help="adaptation seeds per soil and pile (full run: 3)")
    parser.add_argument("--cycles", type=int, default=5, help="cycles per adaptation loop")
    parser.add_argument("--repeats", type=int, default=2, help="runs per sweep mode, alternating order")
    parser.add_argument("--rllib-iterations", type=int, default=4, help="PPO iterations per runner count")
    parser.add_argument("--no-rllib", action="store_true", help="skip the RLlib measurement")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("RAY_DEDUP_LOGS", "1")
    with tempfile.TemporaryDirectory(prefix="scaling-") as tmp:
        work = Path(tmp)
        result = {"benchmark": "scaling", "machine_before": machine_info(),
                  "sweep": sweep_runs(args.seeds, args.cycles, args.repeats, work),
                  "rllib": {"skipped": "--no-rllib"} if args.no_rllib else rllib_runs(args.rllib_iterations, work)}
    result["machine"] = machine_info()
    (out / "scaling.json").write_text(json.dumps(result, indent=1, default=float))
    table = markdown(result)
    (out / "scaling.md").write_text(table + "\n")
    print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
