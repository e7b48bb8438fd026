"""The between-cycles benchmark: its bookkeeping (known answers), its refusals, and a real replay (slow)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from benchmark_scripts import load_benchmark

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "between_cycles.py"
RESULTS = ROOT / "docs" / "results" / "between_cycles"


def _event(kind, cpu, iterations=0, builds=0, ok=True):
    event = {"kind": kind, "cpu_s": cpu, "wall_s": 2 * cpu, "iterations": iterations, "builds": builds,
             "build_cpu_s": 1.5 * builds}
    if kind == "plan":
        event.update(ok=ok, message="m")
    return event


def test_each_cycle_counts_the_calibration_before_it_and_its_plan():
    bc = load_benchmark("between_cycles")
    events = [_event("plan", 0.5, 40), _event("calibration", 0.25), _event("plan", 1.0, 130),
              _event("calibration", 0.125), _event("plan", 4.0, 300, builds=2, ok=False)]
    cycles = bc.between(events)
    assert [c["cycle"] for c in cycles] == [1, 2, 3]
    assert [c["cpu_s"] for c in cycles] == [0.5, 1.25, 4.125]
    assert [c["calibration_cpu_s"] for c in cycles] == [0.0, 0.25, 0.125]
    assert [c["iterations"] for c in cycles] == [40, 130, 300]
    assert [c["nlp_builds"] for c in cycles] == [0, 0, 2] and cycles[2]["nlp_build_cpu_s"] == 3.0
    assert [c["plan_ok"] for c in cycles] == [True, True, False]
    # the oracle does not calibrate: its cycles are its plans
    assert [c["cpu_s"] for c in bc.between([_event("plan", 0.5), _event("plan", 0.75)])] == [0.5, 0.75]


def test_the_summary_is_over_cycles_from_the_second():
    bc = load_benchmark("between_cycles")
    loop = {"cycles": bc.between([_event("plan", 9.0, 500), _event("calibration", 0.5), _event("plan", 1.0, 100),
                                  _event("calibration", 0.5), _event("plan", 2.0, 200, builds=1)])}
    s = bc.summarise({"loops": {"a": loop, "b": loop}})
    assert s["cycles"] == 4
    assert s["cpu_s_median"] == 2.0 and s["cpu_s_max"] == 2.5 and s["cpu_s_total"] == 8.0
    assert s["iterations_median"] == 150 and s["iterations_total"] == 600
    assert s["nlp_builds"] == 2 and s["nlp_build_cpu_s"] == 3.0


@pytest.mark.parametrize("argv, message", [(["--loops", "gravel/0/fixed"], "SOIL/SEED/ours or SOIL/SEED/oracle"),
                                           (["--rounds", "0"], "--rounds must be at least 1"),
                                           (["--cycles", "6"], "--cycles must be 1 to 5"),
                                           (["--from-json"], "--from-json needs --out")])
def test_bad_arguments_are_refused(argv, message):
    done = subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True)
    assert done.returncode == 2 and message in done.stderr


@pytest.mark.parametrize("results", [RESULTS, RESULTS / "learned", RESULTS / "fee", RESULTS / "compiled"],
                         ids=["round1", "learned", "fee", "compiled"])
def test_table_regenerates_from_json(tmp_path, results):
    """Each committed table (round 1; round 2's side-by-side runs and the compiled variant with its compile step)
    is what ``--from-json`` writes from its JSON."""
    if not (results / "between_cycles.json").is_file():
        pytest.skip(f"no committed between-cycles results in {results}")
    shutil.copy(results / "between_cycles.json", tmp_path / "between_cycles.json")
    subprocess.run([sys.executable, str(SCRIPT), "--from-json", "--out", str(tmp_path)], check=True,
                   capture_output=True)
    assert (tmp_path / "table.md").read_text() == (results / "table.md").read_text()
    data = json.loads((results / "between_cycles.json").read_text())
    if data.get("compile_step"):  # the compiled variant: its compile and flag are in the table
        table = (results / "table.md").read_text()
        assert "Compile step" in table and "--compiled DIR" in table
        assert {run["variant"] for run in data["runs"]} == {"baseline", "current", "compiled"}


@pytest.mark.slow
def test_a_replay_makes_the_committed_plans_and_counts_their_work(tmp_path, monkeypatch):
    """Two cycles of the committed gravel loop: the replay plans what was dug (the loop's stale check would stop it
    otherwise), and counts each plan's IPOPT iterations."""
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path / "nlp"))
    out = tmp_path / "replay.json"
    subprocess.run([sys.executable, str(SCRIPT), "--worker", str(out), "--cycles", "2", "--loops", "gravel/0/ours"],
                   check=True, capture_output=True)
    cycles = load_benchmark("between_cycles").between(json.loads(out.read_text())["loops"]["gravel/0/ours"]["events"])
    assert [c["cycle"] for c in cycles] == [1, 2]
    assert all(c["iterations"] > 0 and c["plan_ok"] for c in cycles)
    assert cycles[0]["calibration_cpu_s"] == 0.0 < cycles[1]["calibration_cpu_s"]
