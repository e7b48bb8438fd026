"""Ctrl-C at any moment of a command: exit status 130, the line ``wheelloader: interrupted``, nothing written,
every earlier output as it was (#29).

The commands run as subprocesses and get SIGINT at chosen moments. The smoke test (default suite) interrupts
``plan --pareto`` at three moments; the slow one ``demo`` and ``plan --pareto`` at 20 seeded random moments
each. A moment falls between 1 s (the interpreter's own start-up and the import of ``wheelloader.cli``, 0.1-0.3 s,
keep Python's default: a traceback) and 85 % of the command's own uninterrupted run time, measured in the same
test; a run that still finished (rc 0: the machine sped up, or the signal came after the outputs were in
place, when the command is complete and Ctrl-C is held) must give the uninterrupted run's result byte for
byte, and another moment is drawn.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wheelloader.cli.staging import LOCK_SUFFIX, STAGE_PREFIX
from wheelloader.estimator import preset

PLAN = ["plan", "{params}", "--pareto", "--weights", "0,0.05", "-o", "{out}/plan.csv", "--plot", "{out}/plan.png"]
DEMO = ["demo", "--cycles", "2", "--seeds", "1", "-o", "{out}"]
#: Two seeds side by side in two threads (wheelloader.planner.lanes): a Ctrl-C cancels both lanes.
DEMO_SIDE_BY_SIDE = ["demo", "--cycles", "2", "--seeds", "2", "--jobs", "2", "-o", "{out}"]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _argv(template: list[str], out: Path, params: Path) -> list[str]:
    return [a.format(out=out, params=params) for a in template]


def _run(argv: list[str], cwd: Path, moment: float | None) -> tuple[int, str, bool]:
    """Run ``wheelloader argv``; with ``moment``, send SIGINT that many seconds after the start. Returns the
    exit status, stderr and whether the signal was sent (the run had not ended by then)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "wheelloader.cli", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sent = False
    if moment is not None:
        try:
            proc.wait(timeout=moment)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGINT)
            sent = True
    _, err = proc.communicate(timeout=600)
    return proc.returncode, err, sent


def _no_leftovers(folder: Path) -> None:
    names = [p.name for p in folder.iterdir()]
    assert not [n for n in names if n.startswith(STAGE_PREFIX) or n.endswith(LOCK_SUFFIX)], names


@pytest.fixture()
def params(tmp_path):
    path = tmp_path / "params.json"
    path.write_text(json.dumps({"soil": preset("gravel").to_dict()}))
    return path


def _check_moments(tmp_path: Path, params: Path, template: list[str], moments: int, seed: int,
                   first: float = 1.0) -> list[float]:
    """A complete run into ``done``, then interrupted runs (alternately over ``done`` with --force and into a
    new folder) at ``moments`` seeded random moments; returns the moments that interrupted."""
    done = tmp_path / "done"
    if template is PLAN:
        done.mkdir()
    tic = time.perf_counter()
    code, err, _ = _run(_argv(template, done, params), tmp_path, None)
    full = time.perf_counter() - tic
    assert code == 0, err
    before = _snapshot(done)
    key = "plan.csv" if template is PLAN else "table.md"  # what a complete run gives byte for byte
    rng = random.Random(seed)
    hits: list[float] = []
    for k in range(3 * moments):
        if len(hits) == moments:
            break
        moment = first + rng.random() * (0.85 * full - first)
        replace = k % 2 == 0
        target = done if replace else tmp_path / f"new{k}"
        if template is PLAN and not replace:
            target.mkdir()
        argv = _argv(template, target, params) + (["--force"] if replace else [])
        code, err, sent = _run(argv, tmp_path, moment)
        if code == 0:
            # finished before the signal, or the signal came after the outputs were in place (held, as the
            # command is complete): the result must be the uninterrupted run's (a solve whose interrupt was
            # swallowed gives another plan)
            got = _snapshot(target)
            assert got[key] == before[key], f"SIGINT at {moment:.2f} s (sent: {sent}): rc 0 with another result"
            before = got if replace else before
            continue
        assert code == 130, f"moment {moment:.2f} s: rc {code}\n{err}"
        assert err.strip().splitlines()[-1] == "wheelloader: interrupted", err
        assert "Traceback" not in err, err
        assert _snapshot(done) == before, f"moment {moment:.2f} s changed the earlier outputs"
        if not replace:
            assert not target.exists() or not any(target.iterdir()), f"moment {moment:.2f} s wrote output"
        _no_leftovers(tmp_path)
        _no_leftovers(done)
        hits.append(moment)
    assert len(hits) == moments, f"only {len(hits)} of {moments} moments interrupted the run"
    return hits


def test_ctrl_c_at_three_moments_of_plan_pareto(tmp_path, params):
    _check_moments(tmp_path, params, PLAN, moments=3, seed=29)


@pytest.mark.slow
@pytest.mark.parametrize("template", [DEMO, DEMO_SIDE_BY_SIDE, PLAN], ids=["demo", "demo-side-by-side", "plan-pareto"])
def test_ctrl_c_at_twenty_random_moments(tmp_path, params, template):
    _check_moments(tmp_path, params, template, moments=20, seed=2029)


def test_an_interrupted_solve_is_never_kept_as_a_plan():
    """CasADi swallows the KeyboardInterrupt inside IPOPT (status NonIpopt_Exception_Thrown); the planner
    re-raises it."""
    import threading

    from wheelloader.estimator import Pile
    from wheelloader.planner import PlannerOptions, cycle_duration, default_start, optimizer_for

    opt = optimizer_for(options=PlannerOptions())
    pile = Pile.trapezoid()
    start = default_start(pile)
    duration = cycle_duration(pile, start)
    opt.reset_warm_start()
    timer = threading.Timer(0.3, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt, match="during an IPOPT solve"):  # a cold solve takes seconds
            opt.solve(preset("sand"), pile, start, duration)
    finally:
        timer.cancel()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_in_process_command_gives_the_ctrl_c_handler_back(tmp_path):
    """After its outputs are in place a command holds Ctrl-C until it returns; called in-process (as here),
    it then restores the handler it found."""
    from wheelloader.cli import main
    from wheelloader.estimator import paper_paths, save_path_csv

    save_path_csv(paper_paths()[1], tmp_path / "path.csv")
    assert main(["predict", "gravel", str(tmp_path / "path.csv"), "-o", str(tmp_path / "f.csv")]) == 0
    assert (tmp_path / "f.csv").is_file()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_ctrl_c_inside_the_iteration_callback_stops_the_solve_without_a_traceback(capfd):
    """SIGINT while IPOPT's iteration callback runs: the callback asks IPOPT to stop, and ``guarded`` re-raises
    it after the solve. When the signal lands inside a SWIG call (the callback's ``np.array`` of a DM), SWIG
    hands the ``KeyboardInterrupt`` on as the cause of a ``SystemError``, whose traceback CasADi would print;
    the watcher below lets the signal in and hands it on that way."""
    import casadi as ca

    from wheelloader.planner.interrupt import guarded
    from wheelloader.planner.iteration_monitor import IterationMonitor

    x = ca.MX.sym("x", 2)
    monitor = IterationMonitor(2, 0)
    solver = ca.nlpsol("rosenbrock", "ipopt", {"x": x, "f": (1 - x[0]) ** 2 + 100 * (x[1] - x[0] ** 2) ** 2},
                       {"iteration_callback": monitor, "print_time": False, "ipopt.print_level": 0})
    seen: list[int] = []

    def watch(_x):
        seen.append(1)
        if len(seen) == 3:
            try:
                os.kill(os.getpid(), signal.SIGINT)  # the handler runs at the next bytecode, here
                for _ in range(10**6):
                    pass
            except KeyboardInterrupt as interrupt:
                raise SystemError("DM.__array__ returned a result with an exception set") from interrupt
        return None

    monitor.watch = watch
    capfd.readouterr()
    with pytest.raises(KeyboardInterrupt, match="during an IPOPT solve"):
        guarded(solver, x0=[-1.2, 1.0])
    err = capfd.readouterr().err
    assert len(seen) == 3, "the solve went on after the Ctrl-C"
    assert "Traceback" not in err, err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
