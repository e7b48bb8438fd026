"""Seeds side by side (#31 item 3): ``wheelloader demo --jobs N`` runs its seeds in threads, each planning in its own
lane (:mod:`wheelloader.planner.lanes`), with the same results and progress lines as one seed after another."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from wheelloader.demo import _Streams, default_jobs, run_demo
from wheelloader.estimator import Pile, PlanningError, preset
from wheelloader.planner import PlanOutcome, bezier_on_face, cycle_duration, default_start, lanes, optimizer_for
from wheelloader.planner.memo import RememberedPlanner

#: Summary fields that are times or describe the machine (everything else must match between runs).
TIMING = {"planning_s", "calibration_s", "between_cycles_s", "wall_time_s", "machine"}


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if k not in TIMING}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def test_a_lane_is_set_for_its_block_and_its_cancel_event_is_seen_in_its_thread_only():
    assert lanes.current() == 0 and not lanes.cancelled()
    cancel = threading.Event()
    seen = {}
    with lanes.lane(2, cancel):
        assert lanes.current() == 2
        thread = threading.Thread(target=lambda: seen.update(lane=lanes.current(), cancelled=lanes.cancelled()))
        cancel.set()
        thread.start()
        thread.join()
        assert lanes.cancelled()
        with lanes.lane(1):
            assert lanes.current() == 1 and not lanes.cancelled()
        assert lanes.current() == 2
    assert lanes.current() == 0 and not lanes.cancelled()
    assert seen == {"lane": 0, "cancelled": False}  # another thread keeps its own lane


@pytest.mark.parametrize("bad", [-1, 1.5, True, "1"])
def test_bad_lanes_are_refused(bad):
    with pytest.raises(PlanningError), lanes.lane(bad):
        pass
    with pytest.raises(PlanningError, match="cancel"), lanes.lane(1, cancel=True):
        pass


def test_streams_print_in_the_order_of_a_run_one_after_another():
    printed: list[str] = []
    streams = _Streams([("a", 0), ("a", 1), ("b", 0)], printed.append, threading.Event())
    streams.say(("b", 0), "b0 first")  # a later stream: held
    streams.say(("a", 1), "a1 first")
    streams.say(("a", 0), "a0 first")  # the first stream: printed at once
    assert printed == ["a0 first"]
    streams.done(("b", 0))
    streams.done(("a", 0))  # a1's held line comes out; a1 is now the first stream
    streams.say(("a", 1), "a1 second")
    assert printed == ["a0 first", "a1 first", "a1 second"]
    streams.done(("a", 1))  # b was done already: its held line follows
    assert printed == ["a0 first", "a1 first", "a1 second", "b0 first"]


def test_a_line_said_after_the_cancel_stops_that_run():
    cancel = threading.Event()
    streams = _Streams([0, 1], lambda line: None, cancel)
    streams.say(1, "fine")
    cancel.set()
    with pytest.raises(KeyboardInterrupt):
        streams.say(0, "too late")


def test_default_jobs_is_one_per_seed_up_to_two_per_cpu_and_one_on_one_cpu(monkeypatch):
    import os

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    assert default_jobs(3) == 3 and default_jobs(1) == 1 and default_jobs(20) == 4
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0}, raising=False)
    assert default_jobs(3) == 1


def test_a_soil_and_pile_asked_for_by_two_threads_at_once_are_planned_once():
    calls = []

    def slow(params, pile):
        calls.append(threading.get_ident())
        time.sleep(0.2)
        return PlanOutcome(bezier_on_face(pile), True, "planned", 0.2)

    planner = RememberedPlanner(slow)
    got = []
    threads = [threading.Thread(target=lambda: got.append(planner("sand", Pile.trapezoid()))) for _ in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(calls) == 1 and planner.hits == 2 and len(got) == 3
    assert len({id(outcome) for outcome in got}) == 3  # each caller its own copy
    assert all(np.array_equal(outcome.path.x, got[0].path.x) for outcome in got)


@pytest.fixture(scope="module")
def cycle():
    pile = Pile.trapezoid()
    start = default_start(pile)
    return optimizer_for(), pile, start, cycle_duration(pile, start)


def test_lanes_solving_at_once_give_the_plans_of_one_lane_bit_for_bit(cycle):
    opt, pile, start, duration = cycle
    soils = ("sand", "gravel")
    alone = {soil: opt.solve(preset(soil), pile, start, duration) for soil in soils}
    together = {}

    def solve(lane, soil):
        with lanes.lane(lane):
            together[soil] = opt.solve(preset(soil), pile, start, duration)

    threads = [threading.Thread(target=solve, args=(k + 1, soil)) for k, soil in enumerate(soils)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for soil in soils:
        assert together[soil].iterations == alone[soil].iterations and together[soil].status == alone[soil].status
        np.testing.assert_array_equal(together[soil].x, alone[soil].x)
        np.testing.assert_array_equal(together[soil].z, alone[soil].z)


def test_a_solve_in_a_cancelled_lane_stops_at_its_first_iterate(cycle):
    opt, pile, start, duration = cycle
    cancel = threading.Event()
    cancel.set()
    with lanes.lane(1, cancel):
        plan = opt.solve(preset("sand"), pile, start, duration)
    assert plan.status == "User_Requested_Stop" and plan.iterations <= 1


def test_seeds_side_by_side_give_the_results_and_lines_of_one_seed_after_another(tmp_path):
    runs = {}
    for jobs in (1, 2):
        lines: list[str] = []
        out = tmp_path / f"jobs{jobs}"
        out.mkdir()
        summary = run_demo(out, cycles=2, seeds=3, jobs=jobs, progress=lines.append)
        runs[jobs] = (lines, (out / "table.md").read_bytes(),
                      _without_timing(json.loads((out / "summary.json").read_text(encoding="utf-8"))), summary)
    (lines1, table1, summary1, _), (lines2, table2, summary2, _) = runs[1], runs[2]
    assert table2 == table1
    assert summary2 == summary1
    assert lines2 == lines1
    assert [line for line in lines1 if line.startswith("seed ")] == ["seed 0 (1 of 3):", "seed 1 (2 of 3):",
                                                                     "seed 2 (3 of 3):"]


@pytest.mark.parametrize("kwargs", [{"mpc": True}, {"use_planner": False}, {"plant": "mpm"}])
def test_seeds_side_by_side_need_the_env_plant_with_the_planner_and_no_mpc(tmp_path, kwargs):
    from wheelloader.estimator import ParameterError

    with pytest.raises(ParameterError, match="jobs > 1"):
        run_demo(tmp_path, cycles=1, seeds=2, jobs=2, **kwargs)


def test_a_saved_figure_is_the_same_png_without_the_second_layout_pass(tmp_path):
    """``plotting.finish_figure`` drops the place-holder layout engine ``tight_layout`` leaves before ``savefig``
    (which then skips an undrawn pass over the figure): the file is byte for byte the one saved with it."""
    from wheelloader import plotting

    def figure():
        fig, axes = plotting.new_figure(1, 2, (6, 3))
        axes[0].plot([0, 1, 2], [3, 1, 2], "o-", label="a")
        axes[1].plot([0, 1], [1, 0], "--", label="b")
        for ax in axes:
            ax.set_xlabel("x [m]")
            ax.legend(fontsize=7)
        return fig

    kept = figure()
    kept.suptitle("title")
    kept.tight_layout()
    assert kept.get_layout_engine() is not None  # what savefig would make its second pass for
    kept.savefig(tmp_path / "kept.png", dpi=120)
    plotting._pyplot().close(kept)
    plotting.finish_figure(figure(), tmp_path / "dropped.png", title="title")
    assert (tmp_path / "dropped.png").read_bytes() == (tmp_path / "kept.png").read_bytes()
