"""Time and memory of ``wheelloader demo`` against a baseline revision, side by side (issue #31 item 3).

Each run is the command a user types, ``python -m wheelloader.cli demo -o DIR`` (3 seeds, 5 cycles), in a
fresh process: its CPU time (user + system) and peak resident memory from the kernel (the child's rusage,
``os.wait4``), its wall time, and the load average before and after. The baseline's package is extracted with
``git archive`` into a temporary directory and put first on ``PYTHONPATH`` (each run records the file it
imported). Each version has its own NLP disk cache (``WHEELLOADER_NLP_CACHE``): round 1 starts it empty (the
first run on a machine), later rounds read it. Within a round the versions alternate, so both see the same
load. Every run's ``table.md`` must be byte-identical to the committed ``docs/results/demo/table.md`` and its
``summary.json`` equal to the first baseline run's without the timing and machine fields.

``--stages`` also runs the current demo once more, in-process with a progress hook, and records the CPU time and
resident memory at each of its progress lines (where the time and the memory go), and each thread's own CPU time
and its time spent waiting for a CPU (the seeds run side by side in threads, ``wheelloader demo --jobs``; sampled
every 0.1 s).

Run: ``python benchmarks/demo_speed.py --baseline REV [--rounds 2] [--stages] [--compiled]
[--out docs/results/demo_speed]``; ``--compiled``: the current version's round 1 is ``wheelloader demo --compiled``
(it compiles the planner's derivatives into its empty NLP cache), its later rounds the plain ``wheelloader demo``,
which loads that library; ``--from-json`` rewrites the table and the figure from ``--out``'s ``speed.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: summary.json fields that are timings or describe the machine, left out of the comparison.
TIMING_FIELDS = frozenset({"calibration_s", "planning_s", "between_cycles_s", "wall_time_s", "machine"})
#: The issue's targets: wall time [s] and peak resident memory [MB] of the demo.
TARGETS = {"wall_s": 8.0, "max_rss_mb": 300.0}


def strip_timings(value):
    """``value`` (parsed JSON) without the :data:`TIMING_FIELDS` at any depth."""
    if isinstance(value, dict):
        return {k: strip_timings(v) for k, v in value.items() if k not in TIMING_FIELDS}
    if isinstance(value, list):
        return [strip_timings(v) for v in value]
    return value


def run_demo_process(out: Path, cache: Path, pythonpath: str | None, extra: tuple[str, ...] = ()) -> dict:
    """One ``wheelloader demo`` (with the flags ``extra``) in a fresh process: CPU, wall, peak RSS, load, the module
    it imported."""
    env = dict(os.environ, WHEELLOADER_NLP_CACHE=str(cache))
    env.pop("PYTHONPATH", None)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    code = ("import sys, wheelloader; print('MODULE', wheelloader.__file__, flush=True); "
            "from wheelloader.cli import main; sys.exit(main(['demo', '-o', *sys.argv[1:]]))")
    load_before = os.getloadavg()
    wall = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", code, str(out), *extra], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT)
    output = proc.stdout.read().decode(errors="replace")
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - wall
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"demo failed (exit {proc.returncode}):\n{output[-2000:]}")
    module = next((line.split(" ", 1)[1] for line in output.splitlines() if line.startswith("MODULE ")), "?")
    return {"cpu_s": usage.ru_utime + usage.ru_stime, "user_s": usage.ru_utime, "system_s": usage.ru_stime,
            "wall_s": wall, "max_rss_mb": usage.ru_maxrss / 1024.0, "load_before": load_before,
            "load_after": os.getloadavg(), "module": module}


def compare(out: Path, reference_summary: dict | None) -> dict:
    """``out``'s table against the committed one and its summary against ``reference_summary``."""
    committed = (ROOT / "docs" / "results" / "demo" / "table.md").read_bytes()
    summary = strip_timings(json.loads((out / "summary.json").read_text(encoding="utf-8")))
    return {"table_identical_to_committed": (out / "table.md").read_bytes() == committed,
            "summary_identical_to_first_baseline": reference_summary is None or summary == reference_summary}


def side_by_side(args) -> dict:
    """Rounds of baseline and current demo runs, alternating (module docstring)."""
    runs: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="demo-speed-") as tmp:
        tmp = Path(tmp)
        from wheelloader.provenance import package_at_revision

        commit, pkg = package_at_revision(ROOT, args.baseline, tmp / "baseline")
        reference = None
        for rnd in range(1, args.rounds + 1):
            for version, path in (("baseline", str(pkg)), ("current", None)):
                out = tmp / f"{version}-{rnd}"
                out.mkdir()
                # --compiled: round 1 compiles the derivatives into the current version's empty NLP cache, later
                # rounds are the plain command, which finds that library (planner.nlp.compiled_if_present)
                extra = ("--compiled",) if args.compiled and version == "current" and rnd == 1 else ()
                run = run_demo_process(out, tmp / f"nlp-{version}", path, extra)
                if reference is None:
                    reference = strip_timings(json.loads((out / "summary.json").read_text(encoding="utf-8")))
                run.update(version=version, round=rnd, nlp_cache="empty" if rnd == 1 else "filled", flags=list(extra),
                           **compare(out, reference))
                runs.append(run)
                print(f"round {rnd} {version:8s} cpu {run['cpu_s']:6.2f} s  wall {run['wall_s']:6.2f} s  "
                      f"rss {run['max_rss_mb']:6.1f} MB  load {run['load_before'][0]:.1f}  "
                      f"table {run['table_identical_to_committed']}  "
                      f"summary {run['summary_identical_to_first_baseline']}", flush=True)
        extra = {"stages": stages(tmp / "nlp-current", args.compiled)} if args.stages else {}
    return {"baseline": args.baseline, "baseline_commit": commit, "current_commit": _head(), "runs": runs, **extra}


def _head() -> str:
    done = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return done.stdout.strip() + (" (with uncommitted changes)" if dirty else "")


def stages_worker(out: Path, compiled: bool = False) -> int:
    """Run the current demo in this process; print each progress line with the CPU time and RSS so far."""
    import resource

    from wheelloader.demo import run_demo

    cpu0 = time.process_time()
    wall0 = time.perf_counter()
    stages = []

    def hook(line: str) -> None:
        stages.append({"cpu_s": time.process_time() - cpu0, "wall_s": time.perf_counter() - wall0,
                       "max_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, "line": line})

    # the seeds run side by side in threads (wheelloader demo --jobs; a seed's lines are printed when the seeds
    # before it are done): every 0.1 s each thread's own CPU time and its wait for a CPU so far, the last sample kept
    threads: dict[str, dict] = {}
    stop = threading.Event()

    def sample() -> None:
        while not stop.wait(0.1):
            for thread in threading.enumerate():
                if thread.native_id is not None and thread is not sampler:
                    cpu, queued = _thread_times(thread.native_id)
                    threads[thread.name] = {"cpu_s": cpu, "queued_s": queued}

    sampler = threading.Thread(target=sample, name="sampler", daemon=True)
    sampler.start()
    out.mkdir(parents=True, exist_ok=True)
    run_demo(out, seeds=3, progress=hook, compiled=compiled)
    hook("figures and summary written")
    stop.set()
    sampler.join()
    threads["MainThread"] = dict(zip(("cpu_s", "queued_s"), _thread_times(threading.main_thread().native_id),
                                     strict=True))
    print(json.dumps({"lines": stages, "threads": threads}))
    return 0


def _thread_times(native_id: int) -> tuple[float, float]:
    """A thread's CPU time and its time waiting for a CPU so far [s] (Linux's ``/proc`` schedstat; NaN elsewhere)."""
    try:
        with open(f"/proc/self/task/{native_id}/schedstat", encoding="ascii") as f:
            cpu, queued = f.read().split()[:2]
        return int(cpu) / 1e9, int(queued) / 1e9
    except (OSError, ValueError):
        return math.nan, math.nan


def stages(cache: Path, compiled: bool = False) -> dict:
    """:func:`stages_worker` of the current code in a fresh process (with the NLP cache ``cache``, filled by the
    current version's runs)."""
    with tempfile.TemporaryDirectory(prefix="demo-stages-") as tmp:
        env = dict(os.environ, WHEELLOADER_NLP_CACHE=str(cache))
        flags = ["--compiled"] if compiled else []
        done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--stages-worker", tmp, *flags], env=env,
                              capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def summarise(runs: list[dict]) -> dict:
    """Medians per version and NLP-cache state."""
    summary: dict = {}
    for version in ("baseline", "current"):
        for state in ("empty", "filled"):
            sel = [r for r in runs if r["version"] == version and r["nlp_cache"] == state]
            if sel:
                summary[f"{version}, NLP cache {state}"] = {
                    key: statistics.median(r[key] for r in sel) for key in ("cpu_s", "wall_s", "max_rss_mb")}
    return summary


def markdown(results: dict) -> str:
    """The results note's table: one row per run."""
    lines = ["| round | version | NLP cache | CPU (user + sys) | wall | peak RSS | load (before-after) | table "
             "identical |", "|---|---|---|---|---|---|---|---|"]
    for r in results["runs"]:
        version = r["version"] + "".join(f" `{flag}`" for flag in r.get("flags", ()))
        lines.append(f"| {r['round']} | {version} | {r['nlp_cache']} | {r['cpu_s']:.1f} s | {r['wall_s']:.1f} s "
                     f"| {r['max_rss_mb']:.0f} MB | {r['load_before'][0]:.1f}-{r['load_after'][0]:.1f} | "
                     f"{'yes' if r['table_identical_to_committed'] else 'NO'} |")
    base = results["baseline_commit"][:10]
    flag = " --compiled" if results.get("settings", {}).get("compiled") else ""
    lines.append(f"\n*`python benchmarks/demo_speed.py --baseline {results['baseline']}{flag}` (baseline = {base}, "
                 f"current = {results['current_commit'][:10]}); targets: {TARGETS['wall_s']:g} s wall, "
                 f"{TARGETS['max_rss_mb']:g} MB.*")
    return "\n".join(lines)


def plot(results: dict, path: Path) -> None:
    """CPU, wall and peak RSS of each run, baseline beside current, with the targets."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = results["runs"]
    labels = [f"{r['version']}\nround {r['round']}" for r in runs]
    colors = ["#999999" if r["version"] == "baseline" else "#1f77b4" for r in runs]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8))
    for ax, key, unit, target in ((axes[0], "cpu_s", "CPU time [s]", TARGETS["wall_s"]),
                                  (axes[1], "wall_s", "wall time [s]", TARGETS["wall_s"]),
                                  (axes[2], "max_rss_mb", "peak resident memory [MB]", TARGETS["max_rss_mb"])):
        ax.bar(range(len(runs)), [r[key] for r in runs], color=colors)
        ax.axhline(target, color="k", ls="--", lw=1, label=f"target {target:g}")
        ax.set_xticks(range(len(runs)), labels, fontsize=7)
        ax.set_ylabel(unit)
        ax.legend(fontsize=7)
    loads = [r["load_before"][0] for r in runs]
    fig.suptitle(f"wheelloader demo (3 seeds): baseline {results['baseline_commit'][:10]} (grey) and current "
                 f"{results['current_commit'][:10]} (blue); load {min(loads):.1f}-{max(loads):.1f}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", metavar="REV", help="git revision to compare with (e.g. main)")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of both versions (default: %(default)s)")
    parser.add_argument("--out", default="results/demo_speed", help="output folder (default: %(default)s)")
    parser.add_argument("--stages", action="store_true", help="also the current demo's CPU and memory per stage")
    parser.add_argument("--compiled", action="store_true", help="round 1 runs the current version as "
                        "`wheelloader demo --compiled` (compiles the planner's derivatives into its NLP cache), later "
                        "rounds as plain `wheelloader demo` (which loads that library)")
    parser.add_argument("--from-json", action="store_true", help="rewrite table.md and speed.png from --out's "
                        "speed.json (no runs)")
    parser.add_argument("--stages-worker", metavar="DIR", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.stages_worker:
        return stages_worker(Path(args.stages_worker), args.compiled)
    if args.from_json:
        out = Path(args.out)
        results = json.loads((out / "speed.json").read_text(encoding="utf-8"))
        (out / "table.md").write_text(markdown(results) + "\n", encoding="utf-8")
        plot(results, out / "speed.png")
        return 0
    if not args.baseline:
        parser.error("--baseline REV is required (the revision to run beside the current code)")
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    from wheelloader.provenance import machine_info

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"benchmark": "demo-speed", "machine": machine_info(), "settings": vars(args), **side_by_side(args)}
    results["summary"] = summarise(results["runs"])
    (out / "speed.json").write_text(json.dumps(results, indent=1) + "\n", encoding="utf-8")
    (out / "table.md").write_text(markdown(results) + "\n", encoding="utf-8")
    plot(results, out / "speed.png")
    print(markdown(results))
    ok = all(r["table_identical_to_committed"] and r["summary_identical_to_first_baseline"] for r in results["runs"])
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
