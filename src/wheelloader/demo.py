"""``wheelloader demo``: the cycle-to-cycle adaptation loop on the built-in default.

The plant is the default pile with a hidden gravel-like soil and sensor
noise. Cycle 1 is planned with the nominal parameters (with ``use_planner=False``
it digs the default Bezier path); after each cycle the soil is calibrated (default method, warm-started), the next
cycle's forces are predicted, the next path is planned on the carved pile,
and it is dug. The fixed-path baseline runs beside it for comparison. The
demo prints a per-cycle table and writes figures and a JSON summary.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from wheelloader.cli.output import write_json
from wheelloader.provenance import machine_info

DEFAULT_CYCLES = 5
#: Plant seeds of ``wheelloader demo`` (the table's median and min-max are over them) and the most it accepts.
DEFAULT_SEEDS = 3
MAX_SEEDS = 20
#: The demo's calibration prior (``--prior``; :data:`wheelloader.adaptation.PRIOR_NAMES`): gamma, K and n held
#: softly at the nominal soil, which the demo's hidden soil perturbs. Measured side by side (3 seeds,
#: ``docs/results/identify.md``): cycle 2's prediction 8.4 % instead of 82.5 %, cycles 2-5 7.0 % instead of
#: 23.2 %, fill 98 % instead of 93 %, 22.4 instead of 23.6 kJ/m^3. (The library's ``Calibrating`` default and the
#: other loops stay at :data:`wheelloader.adaptation.DEFAULT_PRIOR`.)
DEMO_PRIOR = "nominal"
#: The tolerance within which another CPU reproduces each column of the demo table (and of a cycle record),
#: half a unit of the table's last printed digit: prediction F_R RMSE [%], fill [fraction of the bucket],
#: energy per m^3 [J/m^3]. docs/reproducibility.md says what was measured against it.
REPRODUCE_TOLERANCE = {"prediction_rmse_percent": 0.05, "fill_fraction": 0.005, "energy_per_m3": 50.0}


#: Plants the demo can dig in (names of :func:`wheelloader.references.make_plant`): the FEE env (the model's own
#: world, fast) and the MPM continuum reference (the DEM plant digs only its own soil presets, not the demo's
#: hidden soil).
DEMO_PLANTS = ("fee-env", "mpm")


def run_demo(out: Path, cycles: int = DEFAULT_CYCLES, seed: int = 0, use_planner: bool = True,
             progress: Any = None, mpc: bool = False, plant: str = "fee-env",
             resolution: float = 0.02, window: int | None = None, seeds: int = 1,
             prior: str | None = None, compiled: bool = False, jobs: int | None = None) -> dict[str, Any]:
    """Run the loop (ours and the fixed baseline), write figures and ``summary.json`` into ``out``.

    ``seeds`` runs of both strategies, with plant seeds ``seed, seed + 1, ...``: ``table.md`` gives each
    cycle's median over them with the min-max beside it (:func:`markdown_table`); the figures show the first
    seed. ``plant="mpm"`` digs every cycle in the plane-strain MPM continuum (grid ``resolution`` [m]; about 3
    minutes per cycle at 2 cm) with the same hidden soil (each cycle saved under ``out/cycles/`` as it finishes,
    ``out/cycles/seedS/`` with several seeds; a second run into the same folder resumes). Both plants run
    :func:`wheelloader.loop.run_loop` on the plant :func:`wheelloader.references.make_plant` makes.
    ``window``: ours calibrates on the last ``window`` cycles together (default
    :data:`wheelloader.adaptation.DEFAULT_WINDOW`). ``prior``: ours' calibration prior at the nominal soil
    (:data:`wheelloader.adaptation.PRIOR_NAMES`; default :data:`DEMO_PRIOR`). ``compiled``: the planner's
    IPOPT derivatives as C compiled once per machine (``PlannerOptions.compiled``; minutes of CPU the first time,
    cached; the same plans and table; without a C compiler CasADi's virtual machine, with a warning); without it
    the demo still uses such a library where this machine has one for its NLP
    (:func:`wheelloader.planner.nlp.compiled_if_present`),
    else CasADi's virtual machine. ``jobs``:
    seeds run side by side in this many threads (:func:`default_jobs` when None; the fee-env plant with the
    planner and without ``mpc`` only, else 1), each planning in its own lane (:mod:`wheelloader.planner.lanes`):
    the same results and progress lines as one after another, in less wall time where the CPUs are free.
    """
    from wheelloader.estimator import ParameterError
    from wheelloader.estimator.checks import check_int

    if plant not in DEMO_PLANTS:
        raise ParameterError(f"plant must be one of {DEMO_PLANTS}, got {plant!r}")
    if plant != "fee-env" and mpc:
        raise ParameterError("--mpc needs the env's feedback and runs only with the fee-env plant")
    seeds = check_int("seeds", seeds, minimum=1, maximum=MAX_SEEDS)
    side_by_side = plant == "fee-env" and use_planner and not mpc
    if jobs is None:
        jobs = default_jobs(seeds) if side_by_side else 1
    jobs = check_int("jobs", jobs, minimum=1, maximum=MAX_SEEDS)
    if jobs > 1 and not side_by_side:
        raise ParameterError("jobs > 1 needs the fee-env plant with the planner and without mpc")
    from wheelloader.adaptation import PRIOR_NAMES, hidden_default_soil

    prior = DEMO_PRIOR if prior is None else prior
    if prior not in PRIOR_NAMES:
        raise ParameterError(f"prior must be one of {PRIOR_NAMES}, got {prior!r}")

    say = progress or (lambda line: None)
    start = time.perf_counter()
    hidden = hidden_default_soil()
    if use_planner:
        say("building the planner's CasADi NLP (once, a few seconds) ...")
        if compiled:
            say("its derivatives as compiled C (compiled once per machine: minutes of CPU the first time) ...")
    from wheelloader.planner.nlp import compiled_if_present, hold_margin_variants

    # the demo's memory budget: a wider-margin re-plan's NLP takes the place of the plan's (rebuilt when needed)
    held = hold_margin_variants(False)
    # the derivatives a --compiled run compiled for the demo's NLP, where this machine has them: the same table
    found = compiled_if_present(True)
    try:
        return _run_demo(out, cycles, seed, use_planner, say, mpc, plant, resolution, window, seeds, prior, start,
                         hidden, compiled, min(jobs, seeds))
    finally:
        hold_margin_variants(held)
        compiled_if_present(found)


def _run_demo(out: Path, cycles: int, seed: int, use_planner: bool, say: Any, mpc: bool, plant: str,
              resolution: float, window: int | None, seeds: int, prior: str, start: float,
              hidden: Any, compiled: bool = False, jobs: int = 1) -> dict[str, Any]:
    """:func:`run_demo` after its checks (with the NLP memory rule set)."""
    from wheelloader.adaptation import DEFAULT_WINDOW, NOMINAL_SOIL, default_planner

    def build_planner() -> Any:
        planner = default_planner(mpc=mpc, compiled=compiled) if use_planner else None
        if planner is not None and not mpc:
            from wheelloader.planner.memo import RememberedPlanner

            # every seed plans cycle 1 with the nominal soil on the same pile: that plan is solved once
            planner = RememberedPlanner(planner)
        return planner

    def run_strategy(s: int, name: str, planner: Any, say_part: Any) -> tuple[list[Any], list[Any]]:
        if name == "ours" and seeds > 1:
            say_part(f"seed {s} ({s - seed + 1} of {seeds}):")
        cache = out / "cycles" if seeds == 1 else out / "cycles" / f"seed{s}"
        return _run_strategy(cache / name, cycles, s, name, planner, plant, hidden, resolution, window, say_part,
                             prior)

    order = list(range(seed, seed + seeds))
    if jobs > 1:
        planner, runs = _side_by_side(order, build_planner, run_strategy, say, jobs)
    else:
        planner = build_planner()
        runs = {s: {name: run_strategy(s, name, planner, say) for name in STRATEGIES} for s in order}
    if planner is not None:
        from wheelloader.planner.nlp import release

        release()  # the planner's NLPs are done with: their memory goes to the figures
    results = runs[seed]
    results_window = DEFAULT_WINDOW if window is None else window
    files = write_figures(out, results)
    table = markdown_table({s: (r["ours"][0], r["fixed"][0]) for s, r in runs.items()})
    (out / "table.md").write_text(table + "\n", encoding="utf-8")
    summary = {
        "plant": ({"kind": "fee-env", "soil": hidden.to_dict(), "sensor_noise_N": 150.0,
                   "pile": "trapezoid 30 deg, 1 m high"} if plant == "fee-env" else
                  {"kind": "mpm", "soil": hidden.to_dict(), "resolution_m": resolution,
                   "pile": "trapezoid 30 deg, 1 m high", "metrics": "energy and fill measured by the plant"}),
        "nominal_soil": NOMINAL_SOIL,
        "calibration_window": results_window,
        "calibration_prior": prior,
        "planner": ("none (Bezier path every cycle)" if planner is None
                    else "CasADi plan + MPC" if mpc else "CasADi plan, tracked"),
        "seeds": list(runs),
        "cycles": {name: [r.to_dict() for r in recs] for name, (recs, _) in results.items()},
        "runs": {str(s): {name: [r.to_dict() for r in recs] for name, (recs, _) in res.items()}
                 for s, res in runs.items()},
        "final_parameters_ours": results["ours"][0][-1].params,
        "reproduce_tolerance": REPRODUCE_TOLERANCE,
        "wall_time_s": time.perf_counter() - start,
        "machine": machine_info(),
        "figures": files,
        "table_markdown": "table.md",
        "table": table,
    }
    write_json(out / "summary.json", summary)
    return summary


def default_jobs(seeds: int) -> int:
    """Threads for ``seeds`` plant seeds side by side: one per seed, at most two per CPU this process may run on;
    1 (one seed after another) on one CPU."""
    import os

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    # one thread per seed where there are CPUs to share: 3 seeds on 2 CPUs end together (2 threads would leave the
    # third seed alone on one CPU at the end)
    return 1 if cpus < 2 else max(1, min(seeds, 2 * cpus))


#: Python's thread switch interval while seeds run side by side [s] (its default is 5 ms): a thread coming back from
#: IPOPT into its iteration callback waits up to this long for the lock Python code of another seed holds. Measured
#: (a 170-iteration solve beside a busy Python thread, load 5-6, three pairs): 7.0-7.7 s wall against 9.6-11.0 s
#: at 5 ms, the same CPU.
SWITCH_INTERVAL = 0.001
#: The demo's strategies, in the order of the summary, the table and the progress lines of each seed.
STRATEGIES = ("ours", "fixed")


def _side_by_side(order: list[int], build_planner: Any, run_strategy: Any, say: Any,
                  jobs: int) -> tuple[Any, dict[int, dict[str, Any]]]:
    """``(planner, {s: {name: run_strategy(s, name, planner, say_part)}})`` for the seeds in ``order``, ``jobs``
    threads at a time, each seed in its own planner lane (:mod:`wheelloader.planner.lanes`).

    Each thread digs its seed's fixed path first, while this thread builds the planner (CasADi lets go of
    Python's lock while it differentiates), then ours. ``say_part`` prints in the order of a run one seed after
    another (:class:`_Streams`). A Ctrl-C (or any error) cancels the lanes: their solves stop at the next
    iterate, and the error is raised once the threads have ended.
    """
    import queue
    import sys
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from wheelloader.planner import lanes

    cancel = threading.Event()
    ready = threading.Event()
    built: dict[str, Any] = {}
    lines = _Streams([(s, name) for s in order for name in STRATEGIES], say, cancel)
    free: queue.SimpleQueue[int] = queue.SimpleQueue()
    for lane in range(jobs):
        free.put(lane)

    def work(s: int) -> dict[str, Any]:
        lane = free.get()
        try:
            with lanes.lane(lane, cancel):
                runs = {}
                for name in reversed(STRATEGIES):  # the fixed path needs no planner: dug while it is built
                    if name != "fixed":
                        while not ready.wait(0.05):
                            lines.check()
                        if "planner" not in built:
                            raise KeyboardInterrupt("the planner was not built")
                    runs[name] = run_strategy(s, name, built.get("planner") if name != "fixed" else None,
                                              lambda line, key=(s, name): lines.say(key, line))
                    lines.done((s, name))
                return {name: runs[name] for name in STRATEGIES}
        finally:
            free.put(lane)

    pool = ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="demo-seed")
    switch = sys.getswitchinterval()
    sys.setswitchinterval(min(switch, SWITCH_INTERVAL))
    try:
        futures = {s: pool.submit(work, s) for s in order}
        try:
            built["planner"] = build_planner()
        finally:
            ready.set()
        return built["planner"], {s: future.result() for s, future in futures.items()}
    except BaseException:
        cancel.set()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        sys.setswitchinterval(switch)


class _Streams:
    """Progress lines of runs side by side, printed as a run one after another prints them: the lines of the
    first unfinished stream (of ``order``) as they come, the later streams' held until every one before is done.
    A line said after ``cancel`` is set raises ``KeyboardInterrupt`` instead (the run stops there)."""

    def __init__(self, order: list[Any], say: Any, cancel: Any) -> None:
        import threading

        self.order, self.say_line, self.cancel = list(order), say, cancel
        self.held: dict[Any, list[str]] = {key: [] for key in order}
        self.finished: set[Any] = set()
        self.lock = threading.Lock()

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` once the runs are cancelled."""
        if self.cancel.is_set():
            raise KeyboardInterrupt("the demo's runs were cancelled")

    def say(self, key: Any, line: str) -> None:
        self.check()
        with self.lock:
            if self.order and self.order[0] == key:
                self.say_line(line)
            else:
                self.held[key].append(line)

    def done(self, key: Any) -> None:
        with self.lock:
            self.finished.add(key)
            while self.order and self.order[0] in self.finished:
                self.order.pop(0)
                if self.order:
                    for line in self.held.pop(self.order[0]):
                        self.say_line(line)


def _run_strategy(cache: Path, cycles: int, seed: int, name: str, planner: Any, plant: str, hidden: Any,
                  resolution: float, window: int | None, say: Any, prior: str) -> tuple[list[Any], list[Any]]:
    """The loop of strategy ``name`` (``"ours"`` or ``"fixed"``) with one plant seed: ``(records, logs)`` (MPM
    cycles saved under ``cache``)."""
    from wheelloader.adaptation import NOMINAL_SOIL, Calibrating, FixedBezier
    from wheelloader.estimator import Pile, preset
    from wheelloader.loop import run_loop
    from wheelloader.references import make_plant

    strategy = (Calibrating(preset(NOMINAL_SOIL), planner=planner, window=window, prior=prior) if name == "ours"
                else FixedBezier(preset(NOMINAL_SOIL)))
    # the FEE env digs every cycle in one env (its sensor noise seen raw); the MPM continuum saves each cycle
    settings = {"keep_env": True} if plant == "fee-env" else {"resolution": resolution}
    say(f"running {cycles} cycles, strategy '{strategy.name}', plant {plant} ...")
    digger = make_plant(plant, **settings)
    try:
        return run_loop(digger, strategy, Pile.trapezoid(), hidden, cycles=cycles, seed=seed,
                        cache=None if plant == "fee-env" else cache, progress=say)
    finally:
        if hasattr(digger, "close"):
            digger.close()


def _spread(values: list[float], fmt: str) -> str:
    """``median (min–max)`` of ``values`` formatted with ``fmt`` (just the value for one seed)."""
    import numpy as np

    med = fmt.format(float(np.median(values)))
    if len(values) == 1:
        return med
    return f"{med} ({fmt.format(min(values))}–{fmt.format(max(values))})"


def markdown_table(runs: dict[int, tuple[list[Any], list[Any]]]) -> str:
    """The README's demo table from ``{seed: (ours' records, fixed's records)}``.

    Per cycle, ours beside the fixed Bézier path: the median over the seeds with the min–max beside it; the
    last row is each seed's mean over cycles 2 to N (after the first calibration), again as median (min–max).
    """
    seeds = list(runs)
    n = len(runs[seeds[0]][0])
    cols = (("prediction_rmse_percent", "{:.1f}", " %"), ("fill_fraction", "{:.0%}", ""),
            ("energy_per_m3", "{:.1f}", ""))

    def value(rec: Any, column: str) -> float:
        v = getattr(rec, column)
        return v / 1e3 if column == "energy_per_m3" else v

    def cells(rows: list[list[Any]]) -> list[str]:
        # rows[seed] = the records to average (one cycle, or cycles 2..N)
        return [_spread([float(sum(value(r, c) for r in recs) / len(recs)) for recs in rows], fmt) + unit
                for c, fmt, unit in cols]

    where = "median (min–max) over seeds " + ", ".join(map(str, seeds)) if len(seeds) > 1 else f"seed {seeds[0]}"
    lines = [f"Each cell: {where}.", "",
             "| cycle | ours: prediction F_R RMSE | ours: fill | ours: kJ/m³ | ours: path | "
             "fixed Bézier: prediction F_R RMSE | fixed: fill | fixed: kJ/m³ |", "|" + "---|" * 8]
    for k in range(n):
        ours = cells([[runs[s][0][k]] for s in seeds])
        fixed = cells([[runs[s][1][k]] for s in seeds])
        planned = sum(runs[s][0][k].plan_ok for s in seeds)
        path = ("planned" if planned == len(seeds) else
                f"planned {planned}/{len(seeds)}, else Bézier, model-placed" if planned else
                "plan failed its check → Bézier, model-placed")
        lines.append(f"| {k + 1} | {' | '.join(ours)} | {path} | {' | '.join(fixed)} |")
    if n > 1:
        ours = cells([runs[s][0][1:] for s in seeds])
        fixed = cells([runs[s][1][1:] for s in seeds])
        lines.append(f"| mean 2–{n} | {' | '.join(ours)} | | {' | '.join(fixed)} |")
    return "\n".join(lines)


def write_figures(out: Path, results: dict[str, Any]) -> list[str]:
    """Observed vs predicted forces, piles and paths, metrics over cycles."""
    import numpy as np

    from wheelloader import plotting
    from wheelloader.estimator import predict, preset

    records, logs = results["ours"]
    n = len(logs)
    fig, axes = plotting.new_figure(1, n, (3.2 * n, 3.2))
    axes = np.atleast_1d(axes)
    for k, (ax, log, rec) in enumerate(zip(axes, logs, records, strict=True)):
        pred = predict(preset(rec.params) if isinstance(rec.params, str) else _soil(rec.params), log)
        plotting.plot_forces(log.path.t, {"measured F_R": log.resultant, "predicted F_R": pred.forces.resultant},
                            ax=ax, styles={"measured F_R": "-", "predicted F_R": "--"})
        ax.set_title(f"cycle {k + 1}: RMSE {rec.prediction_rmse_percent:.1f} %", fontsize=9)
    plotting.finish_figure(fig, out / "forces.png",
                           title="strategy 'ours': measured F_R and the F_R predicted before each cycle")

    fig, ax = plotting.new_figure(1, 1, (9.5, 4))
    paths = [log.path.shifted(name=f"cycle {k + 1}") for k, log in enumerate(logs)]
    plotting.plot_pile_and_paths(logs[0].pile, paths, ax=ax,
                                carved=[log.pile_after for log in logs], x_range=(-0.5, 3.5))
    ax.set_title("pile, paths and the soil each cycle removed ('ours')")
    plotting.finish_figure(fig, out / "piles.png")

    fig, axes = plotting.new_figure(1, 4, (15, 3.4))
    for name, (recs, _) in results.items():
        c = [r.cycle for r in recs]
        axes[0].plot(c, [r.prediction_rmse_percent for r in recs], "o-", label=name)
        axes[1].plot(c, [100 * r.fill_fraction for r in recs], "o-", label=name)
        axes[2].plot(c, [r.energy_per_m3 / 1e3 for r in recs], "o-", label=name)
        if name != "fixed":  # the fixed strategy neither calibrates nor plans
            axes[3].plot(c, [r.between_cycles_s for r in recs], "o-", label=name)
    for ax, label in zip(axes, ("prediction F_R RMSE [%]", "bucket fill [%]", "energy per m³ [kJ/m³]",
                                "calibration + planning [s]"), strict=True):
        ax.set_xlabel("cycle")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    plotting.finish_figure(fig, out / "metrics.png")
    return ["forces.png", "piles.png", "metrics.png"]


def _soil(params: dict[str, float]):
    from wheelloader.estimator import SoilParams

    return SoilParams.from_dict(params)
