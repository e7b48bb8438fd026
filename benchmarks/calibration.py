"""Calibration benchmark: the default method against the paper's two methods, side by side.

Protocol (the paper's train-test protocol, Section IV-B): for each soil, a
noisy synthetic cycle on path 1 of :func:`~wheelloader.estimator.paths.paper_paths`
is the training cycle; paths 2-4 (noisy, other seeds) are the unseen test
cycles. Every method calibrates on the training cycle ``--repeats`` times
(median wall time) and is scored by the F_R RMSE on the training cycle and on
the three test paths, next to the RMSE of the true parameters (the noise
floor). The robustness part draws ``--robustness`` random cycles (random soil
within the paper's bounds, random Bezier path, noise) and counts how often
each method reaches the noise floor (F_R RMSE <= 1.02 x RMSE at the true
parameters); the paper's methods start from the mid-range guess.

BLAS threads are limited to one (``OPENBLAS_NUM_THREADS=1`` etc., set before
numpy loads): every solve here is tiny and thread hand-offs only add noise on
a shared 2-core machine; all methods run under the same setting.

Long logs (issue #13, item 4): ``--long-log 166000 1660000`` instead measures the command line on one
gravel cycle resampled to that many rows, each run in its own process under ``/usr/bin/time -v``
(wall time and peak resident memory; ``getrusage`` where GNU time is missing), and writes
``long_logs.json``.

Speed against an older version (issue #31 item 4): ``--baseline REV`` also times the default method of
git revision ``REV`` (extracted with ``git archive`` into a temporary directory) against the current code
and the multi-stage method, on the training cycles above and on every path-1 cycle of the continuum set
(``--mpm-dir``, default ``data/mpm``). Each version runs in its own worker process; the three are called in
turn, repeat after repeat, so all see the same load. Reported per cycle: the median fit time (the
calibration's ``time_s``, wall clock, as the table above) and CPU time of the whole call, and the training
F_R error of each, with the load average before and after.

Run: ``python benchmarks/calibration.py [--out results/calibration] [--baseline REV]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from wheelloader.provenance import machine_info

METHODS = ("default", "single-stage", "multi-stage")
DEFAULT_SOILS = ("gravel", "dirt", "modified_sand", "lean_clay")


def floor_rmse(cycle, soil, percent: bool = False) -> float:
    """F_R RMSE of the true parameters on the cycle's in-soil samples (the noise floor) [N] (or [%])."""
    from wheelloader.estimator.calibration import predict

    q = predict(soil, cycle).quality
    return q.percent_r if percent else q.rmse_r


def run_soil(name: str, args, rng_seed: int) -> dict:
    """Train on path 1, test on paths 2-4, every method."""
    import numpy as np

    from wheelloader.estimator import paper_paths, preset
    from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
    from wheelloader.estimator.synthetic import synthetic_cycle

    soil = preset(name)
    paths = paper_paths()
    cycles = [synthetic_cycle(soil, p, noise=args.noise, vibration=args.vibration, seed=rng_seed + k)
              for k, p in enumerate(paths)]
    train, tests = cycles[0], cycles[1:]
    out = {"soil": name, "true": soil.to_dict(), "floor_train_rmse_r": floor_rmse(train, soil),
           "floor_train_rmse_r_percent": floor_rmse(train, soil, percent=True),
           "floor_test_rmse_r": [floor_rmse(c, soil) for c in tests], "methods": {}}
    times: dict[str, list[float]] = {m: [] for m in METHODS}
    cals: dict = {}
    for _ in range(args.repeats):  # the methods in turn, repeat after repeat: all see the same load
        for method in METHODS:
            cals[method] = calibrate(train, options=CalibrationOptions(method=method))
            times[method].append(cals[method].time_s)
    for method in METHODS:
        cal = cals[method]
        test_q = [predict(cal, c).quality for c in tests]
        out["methods"][method] = {
            "median_time_s": float(np.median(times[method])),
            "times_s": times[method],
            "nfev": cal.nfev,
            "success": cal.success,
            "message": cal.message,
            "train_rmse": cal.quality.to_dict(),
            "test_rmse_r": [[q.rmse_r, q.percent_r] for q in test_q],
            "test_rmse_r_percent_mean": float(np.mean([q.percent_r for q in test_q])),
            "params": cal.params.to_dict(),
            "K": cal.sinkage_modulus,
            "stages": [s.to_dict() for s in cal.stages],
            "identifiability_status": cal.uncertainty.to_dict()["parameters"],
        }
        out["methods"][method]["_cal"] = cal  # for plotting; removed before writing JSON
    out["_train"] = train
    return out


def run_robustness(count: int, seed: int, args) -> dict:
    """Fraction of random cycles on which each method reaches the noise floor."""
    import numpy as np

    from wheelloader.estimator.calibration import CalibrationOptions, calibrate
    from wheelloader.estimator.synthetic import random_bezier_path, random_soil, synthetic_cycle

    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(count):
        soil, path = random_soil(rng), random_bezier_path(rng)
        cycle = synthetic_cycle(soil, path, noise=args.noise, vibration=args.vibration, seed=rng)
        floor = floor_rmse(cycle, soil)
        row = {"soil": soil.to_dict(), "floor_rmse_r": floor}
        for method in METHODS:
            cal = calibrate(cycle, options=CalibrationOptions(method=method))
            row[method] = {"rmse_r": cal.quality.rmse_r, "ratio": cal.quality.rmse_r / floor,
                           "time_s": cal.time_s, "success": cal.success}
        rows.append(row)
    summary = {m: {"fraction_at_noise_floor": float(np.mean([r[m]["ratio"] <= 1.02 for r in rows])),
                   "median_ratio": float(np.median([r[m]["ratio"] for r in rows])),
                   "median_time_s": float(np.median([r[m]["time_s"] for r in rows]))} for m in METHODS}
    return {"count": count, "seed": seed, "criterion": "F_R RMSE <= 1.02 x RMSE at the true parameters",
            "summary": summary, "cycles": rows}


def plot(results: dict, out: Path) -> None:
    """Fig. 6-style plot of the first soil and a time/RMSE comparison."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wheelloader.plotting import plot_calibration

    first = results["soils"][0]
    plot_calibration(first["_train"], [first["methods"][m]["_cal"] for m in METHODS],
                     out / f"fit_{first['soil']}.png", title=f"training cycle, soil {first['soil']}")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    names = [s["soil"] for s in results["soils"]]
    width = 0.25
    for k, m in enumerate(METHODS):
        xs = [i + (k - 1) * width for i in range(len(names))]
        axes[0].bar(xs, [s["methods"][m]["median_time_s"] * 1e3 for s in results["soils"]], width, label=m)
        axes[1].bar(xs, [s["methods"][m]["test_rmse_r_percent_mean"] for s in results["soils"]], width, label=m)
    for ax, label in zip(axes, ("median calibration time [ms]", "mean F_R RMSE on 3 unseen paths [%]"),
                         strict=True):
        ax.set_xticks(range(len(names)), names)
        ax.set_ylabel(label)
        ax.legend()
    axes[0].set_yscale("log")
    fig.tight_layout()
    fig.savefig(out / "comparison.png", dpi=120)
    plt.close(fig)


def print_table(results: dict) -> None:
    """Side-by-side table of the measured figures."""
    head = (f"{'soil':<14}{'method':<14}{'time ms':>9}{'evals':>7}{'conv':>6}{'train F_R %':>13}"
            f"{'floor %':>9}{'test F_R % (paths 2-4)':>26}")
    print(head)
    print("-" * len(head))
    for s in results["soils"]:
        floor_pct = s["floor_train_rmse_r_percent"]
        for m in METHODS:
            r = s["methods"][m]
            tests = " ".join(f"{v[1]:6.2f}" for v in r["test_rmse_r"])
            print(f"{s['soil']:<14}{m:<14}{r['median_time_s'] * 1e3:9.1f}{r['nfev']:7d}{str(r['success']):>6}"
                  f"{r['train_rmse']['F_R'][1]:13.2f}{floor_pct:9.2f}{tests:>26}")
    sp = results["speedup_multi_over_default"]
    print(f"\nmedian speed-up of 'default' over 'multi-stage': {sp['median']:.2f}x (per soil: "
          + ", ".join(f"{k} {v:.2f}x" for k, v in sp["per_soil"].items()) + ")")
    if "robustness" in results:
        rb = results["robustness"]
        print(f"robustness over {rb['count']} random cycles ({rb['criterion']}):")
        for m, v in rb["summary"].items():
            print(f"  {m:<14} reached the noise floor in {100 * v['fraction_at_noise_floor']:.0f} % "
                  f"(median RMSE/floor {v['median_ratio']:.3f}, median time {v['median_time_s'] * 1e3:.1f} ms)")


def markdown_table(results: dict) -> str:
    """The per-soil table of :func:`print_table` in Markdown (``table.md``), with the robustness summary."""
    lines = ["| soil | method | time ms | evaluations | converged | train F_R % | floor % | unseen paths 2-4 F_R % |",
             "|---|---|---|---|---|---|---|---|"]
    for s in results["soils"]:
        for m in METHODS:
            r = s["methods"][m]
            tests = " / ".join(f"{v[1]:.2f}" for v in r["test_rmse_r"])
            lines.append(f"| {s['soil']} | {m} | {r['median_time_s'] * 1e3:.1f} | {r['nfev']} | {r['success']} | "
                         f"{r['train_rmse']['F_R'][1]:.2f} | {s['floor_train_rmse_r_percent']:.2f} | {tests} |")
    text = "\n".join(lines) + "\n"
    if "robustness" in results:
        rb = results["robustness"]
        text += (f"\nRobustness over {rb['count']} random cycles ({rb['criterion']}): "
                 + "; ".join(f"{m} {100 * v['fraction_at_noise_floor']:.0f} % (median time "
                             f"{v['median_time_s'] * 1e3:.1f} ms)" for m, v in rb["summary"].items()) + ".\n")
    la = results.get("loadavg")
    load = f", load average {la[0]:.1f} before, {results['loadavg_after'][0]:.1f} after" if la else ""
    baseline = results["settings"].get("baseline")
    command = "python benchmarks/calibration.py" + (f" --baseline {baseline}" if baseline else "")
    text += (f"\n*`{command}` ({results['settings']['repeats']} timed calibrations per method and soil, the "
             f"methods in turn; median wall time of the optimisation{load}).*\n")
    return text


def run_long_logs(rows: list[int], out: Path, seed: int) -> list[dict]:
    """Time and peak memory of ``wheelloader calibrate`` on resampled long logs (module docstring)."""
    import re
    import resource
    import shutil
    import subprocess

    import numpy as np

    from wheelloader.estimator import BucketPath, synthetic_cycle

    base = synthetic_cycle("gravel", noise=0.05, seed=seed).path
    gnu_time = Path("/usr/bin/time").exists() and shutil.which("/usr/bin/time") is not None
    found = []
    for n in rows:
        t = np.linspace(base.t[0], base.t[-1], int(n))
        path = BucketPath(t, np.interp(t, base.t, base.x), np.interp(t, base.t, base.z),
                          np.interp(t, base.t, base.blade_angle), name=f"long{n}")
        log = out / f"long_{n}.csv"
        synthetic_cycle("gravel", path, noise=0.05, seed=seed + 1).save(log)
        cmd = [sys.executable, "-m", "wheelloader.cli", "calibrate", str(log), "-o", str(out / f"long_{n}_params.json"),
               "--force"]
        if gnu_time:
            cmd = ["/usr/bin/time", "-v", *cmd]
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
        if match:
            peak_kb = int(match.group(1))
        elif peak_kb <= before:
            peak_kb = None  # getrusage only reports the largest child so far
        record = {"rows": int(n), "csv_mb": log.stat().st_size / 1e6, "exit_code": proc.returncode,
                  "wall_s": wall, "peak_rss_mb": None if peak_kb is None else peak_kb / 1024.0,
                  "decimated": "MAX_FIT_SAMPLES" in proc.stderr}
        found.append(record)
        note = ", fit decimated" if record["decimated"] else ""
        print(f"long log {n:>9} rows ({record['csv_mb']:.0f} MB): exit {proc.returncode}, {wall:.1f} s, "
              f"peak {record['peak_rss_mb'] or float('nan'):.0f} MB{note}")
        log.unlink()
    return found


def several_cycles_timing(args) -> dict:
    """Calibration time (varpro) from one cycle and from five cycles together, ``--repeats`` x each soil (issue #20).

    Cycles: noisy synthetic cycles of each soil on random Bezier paths (the adaptation loop's kind of
    cycle); the five-cycle calibration fits all five together, each on its own pile. Reports the
    calibration's own ``time_s`` (the optimisation) and the wall time of the call (with kinematics and
    the report), medians over every soil and repeat, and the load average before and after.
    """
    import statistics

    import numpy as np

    from wheelloader.estimator.calibration import calibrate
    from wheelloader.estimator.synthetic import random_bezier_path, synthetic_cycle

    calibrate(synthetic_cycle("dirt", noise=0.0))  # warm-up: imports, caches
    load_before = os.getloadavg()
    runs: dict = {"1": {"time_s": [], "wall_s": []}, "5": {"time_s": [], "wall_s": []}}
    for i, name in enumerate(args.soils):
        rng = np.random.default_rng(args.seed + i)
        cycles = [synthetic_cycle(name, random_bezier_path(rng), noise=args.noise, vibration=args.vibration,
                                  seed=args.seed + 100 * i + k) for k in range(5)]
        for rep in range(args.repeats):
            for count, target in (("1", cycles[rep % 5]), ("5", cycles)):
                t0 = time.perf_counter()
                cal = calibrate(target)
                runs[count]["wall_s"].append(time.perf_counter() - t0)
                runs[count]["time_s"].append(cal.time_s)
    summary = {f"{k} cycle(s)": {"median_time_s": statistics.median(v["time_s"]),
                                 "median_wall_s": statistics.median(v["wall_s"]), "calibrations": len(v["time_s"])}
               for k, v in runs.items()}
    return {"benchmark": "calibration-several-cycles", "machine": machine_info(), "settings": vars(args),
            "loadavg_before": load_before, "loadavg_after": os.getloadavg(), "summary": summary, "runs": runs}


# ----------------------------------------------------------------------------- speed against a baseline
#: Layout of the package in the repository (pyproject's package-dir): what a baseline worker imports.
SPEED_METHODS = (("baseline", "default"), ("current", "default"), ("current", "multi-stage"))


def _speed_cycle(spec: dict):
    """The cycle a speed request names: a synthetic training cycle (as :func:`run_soil`'s) or a saved log."""
    from wheelloader.estimator import CycleLog, paper_paths, preset
    from wheelloader.estimator.synthetic import synthetic_cycle

    if spec["kind"] == "log":
        return CycleLog.load(spec["path"])
    return synthetic_cycle(preset(spec["soil"]), paper_paths()[0], noise=spec["noise"], vibration=spec["vibration"],
                           seed=spec["seed"])


def _worker() -> int:
    """Serve speed requests (JSON lines on stdin, one answer per line on stdout) with whatever package is
    importable: the current one, or a baseline's on ``PYTHONPATH``."""
    from wheelloader.estimator import calibration

    def run(cycle, method):
        if hasattr(calibration, "CalibrationOptions"):
            return calibration.calibrate(cycle, options=calibration.CalibrationOptions(method=method))
        return calibration.calibrate(cycle, method)  # a version before CalibrationOptions

    cache: dict = {}
    for line in sys.stdin:
        req = json.loads(line)
        key = json.dumps(req["cycle"], sort_keys=True)
        if key not in cache:
            cache[key] = _speed_cycle(req["cycle"])
            run(cache[key], req["method"])  # warm-up: imports, caches
        wall, cpu = time.perf_counter(), time.process_time()
        cal = run(cache[key], req["method"])
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        print(json.dumps({"fit_s": cal.time_s, "wall_s": wall, "cpu_s": cpu, "nfev": cal.nfev, "cost": cal.cost,
                          "train_rmse_r_percent": cal.quality.percent_r, "params": cal.params.to_dict(),
                          "module": calibration.__file__}), flush=True)
    return 0


def speed_against_baseline(args) -> dict:
    """Fit time of the default method, baseline ``args.baseline`` against the current code, and the
    multi-stage method, interleaved per repeat (module docstring)."""
    specs = [{"name": f"{name} (synthetic)", "kind": "synthetic", "soil": name, "seed": args.seed + 10 * i,
              "noise": args.noise, "vibration": args.vibration} for i, name in enumerate(args.soils)]
    for log in sorted(Path(args.mpm_dir).glob("*_path1.csv")):
        specs.append({"name": f"{log.stem.removesuffix('_path1')} path 1 (MPM)", "kind": "log", "path": str(log)})
    script = str(Path(__file__).resolve())
    with tempfile.TemporaryDirectory(prefix="calibration-baseline-") as tmp:
        from wheelloader.provenance import package_at_revision  # here: the baseline worker runs an older package

        commit, pkg = package_at_revision(Path(__file__).resolve().parents[1], args.baseline, Path(tmp))
        env_base = dict(os.environ)
        workers = {}
        for version, path in (("baseline", str(pkg)), ("current", None)):
            env = dict(env_base)
            if path is not None:
                env["PYTHONPATH"] = path + os.pathsep + env.get("PYTHONPATH", "")
            workers[version] = subprocess.Popen([sys.executable, script, "--worker"], stdin=subprocess.PIPE,
                                                stdout=subprocess.PIPE, text=True, env=env)
        load_before = os.getloadavg()
        rows = []
        try:
            for spec in specs:
                cycle = {k: v for k, v in spec.items() if k != "name"}
                runs: dict = {f"{v} {m}": [] for v, m in SPEED_METHODS}
                for _ in range(args.repeats):
                    for version, method in SPEED_METHODS:
                        w = workers[version]
                        w.stdin.write(json.dumps({"cycle": cycle, "method": method}) + "\n")
                        w.stdin.flush()
                        runs[f"{version} {method}"].append(json.loads(w.stdout.readline()))
                row = {"cycle": spec["name"], "spec": cycle}
                for key, rs in runs.items():
                    row[key] = {"median_fit_s": statistics.median(r["fit_s"] for r in rs),
                                "median_cpu_s": statistics.median(r["cpu_s"] for r in rs),
                                "median_wall_s": statistics.median(r["wall_s"] for r in rs),
                                "train_rmse_r_percent": rs[-1]["train_rmse_r_percent"], "cost": rs[-1]["cost"],
                                "nfev": rs[-1]["nfev"], "params": rs[-1]["params"], "module": rs[-1]["module"]}
                rows.append(row)
                print(_speed_line(row), flush=True)
        finally:
            for w in workers.values():
                w.stdin.close()
                w.wait()
    ratios = [r["current default"]["median_fit_s"] / r["current multi-stage"]["median_fit_s"] for r in rows]
    return {"baseline": args.baseline, "baseline_commit": commit, "repeats": args.repeats,
            "loadavg_before": load_before, "loadavg_after": os.getloadavg(), "cycles": rows,
            "current_over_multi_stage_fit_time": {"median": statistics.median(ratios), "max": max(ratios),
                                                  "cycles_at_or_below_1": sum(v <= 1.0 for v in ratios),
                                                  "cycles": len(ratios)}}


def _speed_line(row: dict) -> str:
    cells = []
    for key in ("baseline default", "current default", "current multi-stage"):
        r = row[key]
        cells.append(f"{r['median_fit_s'] * 1e3:7.1f} ({r['median_cpu_s'] * 1e3:6.1f}) "
                     f"{r['train_rmse_r_percent']:6.2f} %")
    return f"{row['cycle']:<30}" + " | ".join(cells)


def speed_table(speed: dict) -> str:
    """Markdown table of :func:`speed_against_baseline`: fit time, CPU time and training error per cycle."""
    head = ("| cycle | ours, before: fit ms (CPU ms) | ours, now | multi-stage | now / multi-stage | train F_R %: "
            "before / now / multi-stage |\n|---|---|---|---|---|---|\n")
    lines = []
    for r in speed["cycles"]:
        b, c, m = r["baseline default"], r["current default"], r["current multi-stage"]
        lines.append(f"| {r['cycle']} | {b['median_fit_s'] * 1e3:.1f} ({b['median_cpu_s'] * 1e3:.1f}) | "
                     f"{c['median_fit_s'] * 1e3:.1f} ({c['median_cpu_s'] * 1e3:.1f}) | "
                     f"{m['median_fit_s'] * 1e3:.1f} ({m['median_cpu_s'] * 1e3:.1f}) | "
                     f"{c['median_fit_s'] / m['median_fit_s']:.2f} | {b['train_rmse_r_percent']:.2f} / "
                     f"{c['train_rmse_r_percent']:.2f} / {m['train_rmse_r_percent']:.2f} |")
    lb, la = speed["loadavg_before"], speed["loadavg_after"]
    note = (f"\n*`python benchmarks/calibration.py --baseline {speed['baseline']}` (before = "
            f"{speed['baseline_commit'][:10]}); medians of {speed['repeats']} calibrations per cell, the three "
            f"called in turn; fit time = the calibration's `time_s` (wall clock of the optimisation), CPU = the "
            f"whole call; load average {lb[0]:.1f} before, {la[0]:.1f} after.*\n")
    return head + "\n".join(lines) + "\n" + note


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and write ``results.json`` and plots into ``--out``."""
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/calibration", help="output directory (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=20240501, help="random seed (default: %(default)s)")
    parser.add_argument("--soils", nargs="+", default=list(DEFAULT_SOILS), help="soil presets")
    parser.add_argument("--repeats", type=int, default=5, help="timed calibrations per method and soil")
    parser.add_argument("--noise", type=float, default=0.05, help="white noise, fraction of peak F_R")
    parser.add_argument("--vibration", type=float, default=0.02, help="5-15 Hz vibration, fraction of peak F_R")
    parser.add_argument("--robustness", type=int, default=50, help="random cycles for the robustness part (0: skip)")
    parser.add_argument("--long-log", type=int, nargs="+", metavar="ROWS",
                        help="only measure 'wheelloader calibrate' on long logs of these row counts")
    parser.add_argument("--several-cycles", action="store_true",
                        help="only measure calibration from 1 and from 5 cycles together (several_cycles.json)")
    parser.add_argument("--baseline", metavar="REV",
                        help="also time the default method of git revision REV against the current code and the "
                             "multi-stage method (module docstring); writes speed.json and speed.md")
    parser.add_argument("--mpm-dir", default="data/mpm",
                        help="continuum cycles *_path1.csv timed with --baseline (default: %(default)s)")
    parser.add_argument("--speed-only", action="store_true", help="with --baseline: only the speed comparison")
    parser.add_argument("--from-json", action="store_true",
                        help="only rewrite table.md (and speed.md) in --out from its results.json (speed.json)")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return _worker()
    if args.from_json:
        out = Path(args.out)
        (out / "table.md").write_text(markdown_table(json.loads((out / "results.json").read_text())))
        if (out / "speed.json").is_file():
            (out / "speed.md").write_text(speed_table(json.loads((out / "speed.json").read_text())))
        return 0
    if args.speed_only and not args.baseline:
        parser.error("--speed-only needs --baseline REV")
    speed = None
    if args.baseline:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        speed = speed_against_baseline(args)
        speed["machine"] = machine_info()
        (out / "speed.json").write_text(json.dumps(speed, indent=1))
        (out / "speed.md").write_text(speed_table(speed))
        print(speed_table(speed))
        if args.speed_only:
            return 0
    if args.several_cycles:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        found = several_cycles_timing(args)
        (out / "several_cycles.json").write_text(json.dumps(found, indent=1))
        print(json.dumps(found["summary"], indent=1))
        return 0
    if args.long_log:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        found = run_long_logs(args.long_log, out, args.seed)
        (out / "long_logs.json").write_text(json.dumps({"benchmark": "calibration-long-logs", "machine": machine_info(),
                                                        "runs": found}, indent=1))
        return 0

    import numpy as np

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    from wheelloader.estimator.calibration import calibrate
    from wheelloader.estimator.synthetic import synthetic_cycle

    calibrate(synthetic_cycle("dirt", noise=0.0))  # warm-up: imports, caches
    load_before = os.getloadavg()
    soils = [run_soil(name, args, args.seed + 10 * i) for i, name in enumerate(args.soils)]
    per_soil = {s["soil"]: s["methods"]["multi-stage"]["median_time_s"] / s["methods"]["default"]["median_time_s"]
                for s in soils}
    results = {"benchmark": "calibration", "machine": machine_info(), "settings": vars(args),
               "rmse_definition": "F_R RMSE over in-soil samples; % = 100 RMSE / mean(|F_R observed|)",
               "soils": soils,
               "speedup_multi_over_default": {"median": float(np.median(list(per_soil.values()))),
                                              "per_soil": per_soil}}
    if args.robustness > 0:
        results["robustness"] = run_robustness(args.robustness, args.seed + 999, args)
    results["wall_time_s"] = time.perf_counter() - t0
    results["loadavg"], results["loadavg_after"] = load_before, os.getloadavg()
    if speed is not None:
        results["speed_against_baseline"] = "speed.json"
    plot(results, out)
    print_table(results)
    for s in soils:
        s.pop("_train")
        for m in s["methods"].values():
            m.pop("_cal")
    (out / "results.json").write_text(json.dumps(results, indent=1, default=float))
    (out / "table.md").write_text(markdown_table(results))
    print(f"\nresults written to {out.resolve()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
