"""The work between cycles of the MPM loop, replayed on its committed cycles, against a baseline revision (#33, #31).

The acceptance run of the MPM loop (``benchmarks/loop_mpm.sh``) saved every cycle it dug under
``data/results/loop_mpm/cycles/loops/SOIL/seedS/STRATEGY``. Replaying a loop runs its strategy again with the run's
settings (:data:`LOOP_SETTINGS`) through :func:`wheelloader.loop.plant_loop_unit`: after each cycle it calibrates on
the saved log, plans the next cycle on the saved carved pile, and the saved cycle is resumed instead of dug
(``stale="keep"``: the saved cycle is used even where today's code plans another path; each plan's path digest is
recorded, and the summary counts the plans equal to the dug ones and to the baseline's). What is measured is
exactly the work between cycles, on the machine's CPU clock (``time.process_time``, not the wall clock
that the loop's records and the acceptance table carry): per cycle the calibration after the previous cycle and
the plan of this one, the IPOPT iterations the plan spent (its re-plans included) and the NLPs it had to build
(``casadi.nlpsol`` calls and their CPU).

Each variant runs in a fresh process and they alternate within one invocation: ``baseline`` is the package at
``--baseline REV`` and ``current`` the package at ``--current REV`` (default ``HEAD``), each extracted with
:func:`wheelloader.provenance.package_at_revision` and put first on ``PYTHONPATH`` (so edits made while it runs do
not leak in). Each version has its own NLP disk cache (``WHEELLOADER_NLP_CACHE``): round 1 starts it empty (the
NLPs' expressions are built then, inside the first plan that needs them), later rounds read it.

Run: ``python benchmarks/between_cycles.py --baseline REV [--current REV] [--rounds 2]
[--out docs/results/between_cycles]``; ``--from-json`` rewrites the table from ``--out``'s ``between_cycles.json``.
``--run JSON`` replays the loops of another ``plant_adaptation.py`` run with its settings (its JSON's ``settings``:
prior, payload, descend clearance, look-ahead, ...; its saved cycles unless ``--cycles-dir``), e.g. the look-ahead
arm of ``benchmarks/lookahead_mpm.sh``; ``--single`` replays the current version only. Each plan's CPU is split
into its IPOPT solves (``TrajectoryOptimizer.solve``: IPOPT with its iteration callback's NumPy checks, the
look-ahead's candidates and second cycles included) and the rest (the kept target, the final check, NLP builds,
the look-ahead's scoring). ``--compiled DIR`` adds a third variant, ``compiled``: the current package with the
IPOPT derivatives compiled as C (``plant_adaptation.py --compiled``; every loop uses such libraries where present,
:func:`wheelloader.planner.nlp.compiled_if_present`). Before the rounds it replays cycle 1 of the first loop with
``compiled=True`` and the NLP disk cache ``DIR`` (the compile, recorded with its CPU and peak memory; nothing to
compile when ``DIR`` has the libraries already); in each round the variant starts from an empty NLP disk cache with
``DIR``'s libraries copied in. Only the NLPs that the compile step planned with are compiled (the plan's; the
wider-margin re-plans' NLPs are compiled only when that cycle re-plans), the others stay in CasADi's VM.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The acceptance run's loop settings (``benchmarks/loop_mpm.sh``'s COMMON; angles in radians).
LOOP_SETTINGS = {"cycles": 5, "failure_angle": "min_weight_force", "heel_clearance": 0.0,
                 "end_blade_angle": math.radians(55.0), "curl_out_intervals": 8, "midpoints": False,
                 "objective": "kept_per_energy", "fill_limit": None}
#: The loops replayed by default: the learning strategies of seed 0 (``phase2``'s loops, oracle parameters there).
DEFAULT_LOOPS = ("gravel/0/ours", "sand/0/ours", "gravel/0/oracle", "sand/0/oracle")
CYCLES = ROOT / "data" / "results" / "loop_mpm" / "cycles" / "loops"
ORACLE_PARAMS = ROOT / "docs" / "results" / "loop_mpm" / "phase2" / "plant_adaptation.json"
#: The issue's target: the median time between cycles [s] (#33).
TARGET_S = 1.0
#: Set to "1" in the worker of ``--compiled``'s compile step: its loop plans with ``compiled=True``.
COMPILE_ENV = "WHEELLOADER_BETWEEN_CYCLES_COMPILE"


def run_settings(run: Path) -> tuple[dict, Path]:
    """:func:`wheelloader.loop.plant_loop_unit`'s loop keywords of a ``plant_adaptation.py`` run (its JSON's
    ``settings``; ``cycles`` its cycles per loop) and the folder of its saved cycles."""
    from wheelloader.arguments import planner_physics
    from wheelloader.estimator import PayloadOptions

    st = json.loads(run.read_text(encoding="utf-8"))["settings"]
    payload = st.get("payload")
    loop = {"cycles": int(st["cycles"]), "failure_angle": st["failure_angle"], "objective": st["objective"],
            "fill_limit": st.get("fill_limit_used"), "lookahead": st.get("lookahead", False),
            "prior": st.get("prior", "none"), "descend_clearance": st.get("descend_clearance"),
            "payload": None if payload is None else _payload(ROOT / payload, PayloadOptions),
            "force_model": st.get("force_model", "fee"), **planner_physics(argparse.Namespace(**st))}
    return loop, ROOT / st["cycles_dir"]


def _payload(path: Path, options: type) -> dict:
    """The payload state of a run's ``--payload`` JSON (``transfer.json``'s ``"payload"``, or the file itself)."""
    data = json.loads(path.read_text(encoding="utf-8"))
    return options.from_dict(data.get("payload", data) if isinstance(data, dict) else data).to_dict()


def worker(loops: list[str], cycles_dir: Path, out: Path, cycles: int = LOOP_SETTINGS["cycles"],
           run: Path | None = None) -> int:
    """Replay the first ``cycles`` cycles of ``loops`` in this process (the loop settings of ``run``'s
    ``plant_adaptation.py`` JSON where given, else :data:`LOOP_SETTINGS`); write the calibrations' and plans' CPU,
    iterations, IPOPT solves' CPU and NLP builds (and the imports' CPU) to ``out`` (JSON)."""
    cpu0 = time.process_time()
    import casadi

    import wheelloader
    from wheelloader.adaptation import Calibrating
    from wheelloader.estimator import SoilParams
    from wheelloader.loop import plant_loop_unit
    from wheelloader.planner.trajectory import TrajectoryOptimizer
    from wheelloader.references import make_plant
    from wheelloader.saved_loops import load_saved_cycle, path_digest

    settings = LOOP_SETTINGS if run is None else run_settings(run)[0]
    event: dict = {"iterations": 0, "builds": 0, "build_cpu_s": 0.0, "solve_cpu_s": 0.0, "folder": None}
    rows: list[dict] = []

    def counted_nlpsol(*args, **kwargs):
        tic = time.process_time()
        try:
            return real_nlpsol(*args, **kwargs)
        finally:
            event["builds"] += 1
            event["build_cpu_s"] += time.process_time() - tic

    def counted_solve(self, *args, **kwargs):
        tic = time.process_time()
        plan = real_solve(self, *args, **kwargs)
        event["solve_cpu_s"] += time.process_time() - tic
        event["iterations"] += int(plan.iterations)
        return plan

    def timed(kind, method):
        def wrapper(self, *args, **kwargs):
            event.update(iterations=0, builds=0, build_cpu_s=0.0, solve_cpu_s=0.0)
            tic, wall = time.process_time(), time.perf_counter()
            result = method(self, *args, **kwargs)
            row = {"kind": kind, "cpu_s": time.process_time() - tic, "wall_s": time.perf_counter() - wall,
                   "iterations": event["iterations"], "builds": event["builds"], "build_cpu_s": event["build_cpu_s"],
                   "solve_cpu_s": event["solve_cpu_s"]}
            if kind == "plan":
                digest = None if result.path is None else path_digest(result.path)
                saved = load_saved_cycle(event["folder"], sum(r["kind"] == "plan" for r in rows) + 1)
                row.update(ok=bool(result.success), message=str(result.message)[:160], digest=digest,
                           as_dug=saved is not None and digest == saved.metadata.get("planned_path_sha256"))
            rows.append(row)
            return result
        return wrapper

    real_nlpsol, real_solve = casadi.nlpsol, TrajectoryOptimizer.solve
    casadi.nlpsol = counted_nlpsol
    TrajectoryOptimizer.solve = counted_solve
    Calibrating.plan = timed("plan", Calibrating.plan)
    Calibrating.update = timed("calibration", Calibrating.update)
    oracle = json.loads(ORACLE_PARAMS.read_text(encoding="utf-8"))["oracle"]
    plant = make_plant("mpm", resolution=0.02, threads=2)
    result = {"module": wheelloader.__file__, "import_cpu_s": time.process_time() - cpu0, "loops": {}}
    for loop in loops:
        soil, seed, strategy = loop.split("/")
        rows.clear()
        tic = time.process_time()
        extra = {"oracle_params": SoilParams.from_dict(oracle[soil]["params"])} if strategy == "oracle" else {}
        event["folder"] = cycles_dir / soil / f"seed{seed}" / strategy
        compiled = os.environ.get(COMPILE_ENV) == "1"
        plant_loop_unit(plant, strategy, soil, seed=int(seed), stale="keep", planner=True, cache=event["folder"],
                        **{**settings, "cycles": cycles}, **extra, **({"compiled": True} if compiled else {}))
        result["loops"][loop] = {"cpu_s": time.process_time() - tic, "events": list(rows)}
    out.write_text(json.dumps(result), encoding="utf-8")
    return 0


def between(events: list[dict]) -> list[dict]:
    """Per cycle: the calibration after the previous cycle (none before cycle 1, none for the oracle) and the
    plan of this cycle, summed."""
    cycles: list[dict] = []
    pending: dict | None = None
    for e in events:
        if e["kind"] == "calibration":
            pending = e
            continue
        calib = pending or {"cpu_s": 0.0, "wall_s": 0.0, "builds": 0, "build_cpu_s": 0.0}
        cycles.append({"cycle": len(cycles) + 1, "calibration_cpu_s": calib["cpu_s"], "plan_cpu_s": e["cpu_s"],
                       "cpu_s": calib["cpu_s"] + e["cpu_s"], "wall_s": calib["wall_s"] + e["wall_s"],
                       "iterations": e["iterations"], "nlp_builds": e["builds"] + calib["builds"],
                       "nlp_build_cpu_s": e["build_cpu_s"] + calib["build_cpu_s"], "plan_ok": e["ok"],
                       "solve_cpu_s": e.get("solve_cpu_s", math.nan),
                       "message": e["message"], "digest": e.get("digest"), "as_dug": e.get("as_dug")})
        pending = None
    return cycles


def run_worker(variant: str, pythonpath: str | None, loops: list[str], cycles_dir: Path, tmp: Path,
               cycles: int = LOOP_SETTINGS["cycles"], run: Path | None = None, nlp_cache: Path | None = None,
               compile_: bool = False) -> dict:
    """One replay in a fresh process (NLP disk cache ``nlp_cache`` or ``tmp/nlp-VARIANT``; ``compile_``: the loop
    plans with ``compiled=True``); its rows and its CPU, wall, peak memory and load."""
    env = dict(os.environ, WHEELLOADER_NLP_CACHE=str(nlp_cache or tmp / f"nlp-{variant}"))
    env.pop(COMPILE_ENV, None)
    if compile_:
        env[COMPILE_ENV] = "1"
    env.pop("PYTHONPATH", None)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    out = tmp / f"{variant}-{time.monotonic_ns()}.json"
    load = os.getloadavg()
    wall = time.perf_counter()
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(out), "--cycles-dir", str(cycles_dir),
               "--cycles", str(cycles), "--loops", *loops, *([] if run is None else ["--run", str(run)])]
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    output = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{variant} replay failed:\n{output[-3000:]}")
    result = json.loads(out.read_text(encoding="utf-8"))
    result.update(variant=variant, process_cpu_s=usage.ru_utime + usage.ru_stime,
                  wall_s=time.perf_counter() - wall, max_rss_mb=usage.ru_maxrss / 1024.0, load_before=load,
                  load_after=os.getloadavg())
    for loop in result["loops"].values():
        loop["cycles"] = between(loop.pop("events"))
    return result


def summarise(run: dict) -> dict:
    """Medians over every replayed cycle from cycle 2 (as the acceptance table's "between cycles")."""
    cycles = [c for loop in run["loops"].values() for c in loop["cycles"] if c["cycle"] >= 2]
    med = (lambda key: statistics.median(c[key] for c in cycles)) if cycles else (lambda key: math.nan)  # noqa: E731
    return {"cycles": len(cycles), "cpu_s_median": med("cpu_s"), "calibration_cpu_s_median": med("calibration_cpu_s"),
            "plan_cpu_s_median": med("plan_cpu_s"), "iterations_median": med("iterations"),
            "solve_cpu_s_median": med("solve_cpu_s"),
            "plan_rest_cpu_s_median": statistics.median(c["plan_cpu_s"] - c["solve_cpu_s"] for c in cycles)
            if cycles and all("solve_cpu_s" in c for c in cycles) else math.nan,
            "cpu_s_max": max((c["cpu_s"] for c in cycles), default=math.nan),
            "cpu_s_total": sum(c["cpu_s"] for c in cycles),
            "nlp_builds": sum(c["nlp_builds"] for c in cycles),
            "nlp_build_cpu_s": sum(c["nlp_build_cpu_s"] for c in cycles),
            "iterations_total": sum(c["iterations"] for c in cycles),
            "plans_as_dug": sum(bool(c["as_dug"]) for loop in run["loops"].values() for c in loop["cycles"]),
            "plans": sum(len(loop["cycles"]) for loop in run["loops"].values())}


def same_plans(run: dict, reference: dict) -> int:
    """How many of ``run``'s plans have the path digest of ``reference``'s plan of the same loop and cycle."""
    return sum(c["digest"] == r["digest"] for name, loop in run["loops"].items()
               for c, r in zip(loop["cycles"], reference["loops"][name]["cycles"], strict=True))


def markdown(data: dict) -> str:
    """The side-by-side table (one row per run) and the per-cycle table of the last round."""
    lines = ["| round | version | NLP disk cache | between cycles, CPU median (max) | calibration / plan, CPU "
             "median | IPOPT iterations median (total) | NLPs built between cycles (their CPU) | plans as dug / as "
             "the first baseline's | replay CPU / wall | load (before-after) |", "|" + "---|" * 10]
    for run in data["runs"]:
        s = run["summary"]
        lines.append(f"| {run['round']} | {run['variant']} | {run['nlp_cache']} | "
                     f"{s['cpu_s_median']:.2f} s ({s['cpu_s_max']:.2f} s) | "
                     f"{s['calibration_cpu_s_median']:.2f} / {s['plan_cpu_s_median']:.2f} s | "
                     f"{s['iterations_median']:.0f} ({s['iterations_total']}) | {s['nlp_builds']} "
                     f"({s['nlp_build_cpu_s']:.1f} s) | {s['plans_as_dug']} / {s['plans_as_first_baseline']} of "
                     f"{s['plans']} | {run['process_cpu_s']:.1f} / {run['wall_s']:.1f} s | "
                     f"{run['load_before'][0]:.1f}-{run['load_after'][0]:.1f} |")
    last = {}
    for run in data["runs"]:
        last[run["variant"]] = run
    lines += ["", "| loop | cycle | " + " | ".join(f"{v}: CPU (calibration + plan), iterations, NLPs built"
                                                  for v in last) + " |", "|" + "---|" * (2 + len(last))]
    first = next(iter(last.values()))
    for name, loop in first["loops"].items():
        for k, c in enumerate(loop["cycles"]):
            cells = []
            for run in last.values():
                o = run["loops"][name]["cycles"][k]
                solve = o.get("solve_cpu_s")
                cells.append(f"{o['cpu_s']:.2f} s ({o['calibration_cpu_s']:.2f} + {o['plan_cpu_s']:.2f}"
                             + ("" if solve is None or math.isnan(solve) else f", IPOPT solves {solve:.2f}")
                             + f"), {o['iterations']} it., {o['nlp_builds']}"
                             + ("" if o["plan_ok"] else ", plan failed"))
            lines.append(f"| {name} | {c['cycle']} | " + " | ".join(cells) + " |")
    solves = [run["summary"].get("solve_cpu_s_median") for run in data["runs"]]
    if any(v is not None and not math.isnan(v) for v in solves):
        lines += ["", "| round | version | between cycles, CPU median | calibration | plan | of the plan: IPOPT "
                  "solves | of the plan: the rest |", "|" + "---|" * 7]
        for run in data["runs"]:
            s = run["summary"]
            lines.append(f"| {run['round']} | {run['variant']} | {s['cpu_s_median']:.2f} s | "
                         f"{s['calibration_cpu_s_median']:.2f} s | {s['plan_cpu_s_median']:.2f} s | "
                         f"{s['solve_cpu_s_median']:.2f} s | {s['plan_rest_cpu_s_median']:.2f} s |")
    single = all(run["variant"] != "baseline" for run in data["runs"])
    step = data.get("compile_step")
    command = " ".join(part for part in (
        "" if single else f"--baseline {data['baseline']}",
        "" if single or data.get("current", "HEAD") == "HEAD" else f"--current {data['current']}",
        "" if "run" not in data else f"--run {data['run']}", "--single" if single else "",
        "" if step is None else "--compiled DIR",
        "" if "run" not in data else f"--cycles {data['settings']['cycles']} --loops {' '.join(data['loops'])}",
        "" if max(r['round'] for r in data['runs']) == 2 else f"--rounds {max(r['round'] for r in data['runs'])}")
        if part)
    versions = (f"current = {data['current_commit'][:10]}" if single else
                f"baseline = {data['baseline_commit'][:10]}, current = {data['current_commit'][:10]}")
    if step is not None:
        lines += ["", f"Compile step (`compiled=True`, cycle 1 of {next(iter(step['loops']))}, NLP disk cache DIR): "
                  f"{step['process_cpu_s']:.0f} s CPU, {step['wall_s']:.0f} s wall, peak {step['max_rss_mb']:.0f} MB, "
                  f"load {step['load_before'][0]:.1f}-{step['load_after'][0]:.1f}; libraries "
                  + ", ".join(f"`{name}`" for name in step.get("libraries", [])) + "."]
    lines += ["", f"*`python benchmarks/between_cycles.py {command}` ({versions}); CPU seconds of this "
              f"process (`time.process_time`); target {TARGET_S:g} s median (#33).*"]
    return "\n".join(lines)


def side_by_side(args: argparse.Namespace) -> dict:
    """Alternating replays of the baseline and the current package (module docstring)."""
    from wheelloader.provenance import package_at_revision

    runs = []
    with tempfile.TemporaryDirectory(prefix="between-cycles-") as tmp:
        tmp = Path(tmp)
        commit, pkg = package_at_revision(ROOT, args.baseline, tmp / "baseline")
        current, current_pkg = package_at_revision(ROOT, args.current, tmp / "current")
        reference = None
        variants = (("current", current_pkg),) if args.single else (("baseline", pkg), ("current", current_pkg))
        compile_step = None
        if args.compiled is not None:
            variants += (("compiled", current_pkg),)
            compile_step = run_worker("compile", str(current_pkg), args.loops[:1], args.cycles_dir, tmp, 1, args.run,
                                      nlp_cache=args.compiled.resolve(), compile_=True)
            compile_step["libraries"] = sorted(p.name for p in (args.compiled / "compiled").glob("*.so"))
            print(f"compile step: {compile_step['process_cpu_s']:.1f} s CPU, {compile_step['wall_s']:.1f} s wall, "
                  f"peak {compile_step['max_rss_mb']:.0f} MB, libraries {compile_step['libraries']}", flush=True)
        for rnd in range(1, args.rounds + 1):
            for variant, path in variants:
                cache = None
                if variant == "compiled":
                    cache = tmp / f"nlp-compiled-{rnd}"
                    (cache / "compiled").mkdir(parents=True)
                    for library in (args.compiled / "compiled").glob("*.so"):
                        shutil.copy2(library, cache / "compiled" / library.name)
                run = run_worker(variant, str(path), args.loops, args.cycles_dir, tmp, args.cycles, args.run,
                                 nlp_cache=cache)
                reference = reference or run
                run.update(round=rnd, nlp_cache="empty" if rnd == 1 else "filled", summary=summarise(run))
                run["summary"]["plans_as_first_baseline"] = same_plans(run, reference)
                runs.append(run)
                s = run["summary"]
                print(f"round {rnd} {variant:8s} median {s['cpu_s_median']:.2f} s CPU (calibration "
                      f"{s['calibration_cpu_s_median']:.2f}, plan {s['plan_cpu_s_median']:.2f}), "
                      f"{s['iterations_median']:.0f} it., NLPs built {s['nlp_builds']} "
                      f"({s['nlp_build_cpu_s']:.1f} s), load {run['load_before'][0]:.1f}", flush=True)
    return {"baseline": args.baseline, "baseline_commit": commit, "current": args.current, "current_commit": current,
            "loops": list(args.loops), "runs": runs, "compile_step": compile_step,
            "settings": {**(LOOP_SETTINGS if args.run is None else run_settings(args.run)[0]), "cycles": args.cycles},
            **({} if args.run is None else {"run": str(args.run)})}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", default="HEAD", help="git revision of the baseline (default: %(default)s)")
    parser.add_argument("--current", default="HEAD", help="git revision of the current version (default: %(default)s)")
    parser.add_argument("--rounds", type=int, default=2,
                        help="rounds of baseline and current (default 2: the first with empty NLP disk caches)")
    parser.add_argument("--loops", nargs="+", default=list(DEFAULT_LOOPS), metavar="SOIL/SEED/STRATEGY",
                        help="the committed loops to replay (default: %(default)s)")
    parser.add_argument("--cycles", type=int, default=None,
                        help="replay the first CYCLES cycles of each loop (default: all, 5 or --run's)")
    parser.add_argument("--cycles-dir", type=Path, default=None,
                        help="the saved cycles (default: the committed, or --run's)")
    parser.add_argument("--run", type=Path, default=None, metavar="JSON",
                        help="replay with the loop settings of this plant_adaptation.py run (its JSON)")
    parser.add_argument("--single", action="store_true", help="replay the current version only (no baseline)")
    parser.add_argument("--compiled", type=Path, default=None, metavar="DIR",
                        help="add the current version with compiled derivatives (compiled into DIR's NLP cache "
                             "first when not there: minutes of CPU)")
    parser.add_argument("--out", type=Path, default=None, help="write between_cycles.json and table.md here")
    parser.add_argument("--from-json", action="store_true", help="rewrite --out's table.md from its JSON")
    parser.add_argument("--worker", type=Path, default=None, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.run is not None and not args.run.is_file():
        parser.error(f"--run {args.run}: no such file")
    most, saved = (LOOP_SETTINGS["cycles"], CYCLES) if args.run is None else (
        run_settings(args.run)[0]["cycles"], run_settings(args.run)[1])
    args.cycles = most if args.cycles is None else args.cycles
    args.cycles_dir = saved if args.cycles_dir is None else args.cycles_dir
    if args.worker is not None:
        return worker(args.loops, args.cycles_dir, args.worker, args.cycles, args.run)
    for loop in args.loops:
        parts = loop.split("/")
        if len(parts) != 3 or parts[2] not in ("ours", "oracle") or not parts[1].isdigit():
            parser.error(f"a loop is SOIL/SEED/ours or SOIL/SEED/oracle, got {loop!r}")
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    if not 1 <= args.cycles <= most:
        parser.error(f"--cycles must be 1 to {most}")
    if args.from_json:
        if args.out is None:
            parser.error("--from-json needs --out")
        data = json.loads((args.out / "between_cycles.json").read_text(encoding="utf-8"))
    else:
        data = side_by_side(args)
    table = markdown(data)
    print(table)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        if not args.from_json:
            (args.out / "between_cycles.json").write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
        (args.out / "table.md").write_text(table + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
