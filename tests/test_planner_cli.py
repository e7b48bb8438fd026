"""``wheelloader plan`` end to end, and the Pareto sweep behind ``--pareto``.

Every planner solve takes 0.1-2 s here and the NLP is built once per worker
(about 2 s per option set), so the solving tests are few and use short sweeps;
the bad-input tests fail before anything is solved.
"""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from wheelloader.cli import main
from wheelloader.estimator import Pile, preset
from wheelloader.estimator.cyclelog import load_path_csv
from wheelloader.estimator.synthetic import synthetic_cycle
from wheelloader.planner import PlannerOptions, mark_pareto_optimal, pareto_sweep, path_energy
from wheelloader.planner.pareto import ParetoPoint

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _read(csv_path):
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def test_calibrate_then_plan_with_plot(tmp_path, capsys):
    """params.json as `wheelloader calibrate` writes it -> a checked plan, CSV, summary and figure."""
    log = tmp_path / "log.csv"
    synthetic_cycle("gravel", noise=0.0).save(log)
    params = tmp_path / "params.json"
    assert main(["calibrate", str(log), "-o", str(params)]) == 0
    capsys.readouterr()
    out_csv, plot = tmp_path / "plan.csv", tmp_path / "plan.png"
    assert main(["plan", str(params), "-o", str(out_csv), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    for text in ("IPOPT", "ms", "fill", "kJ/m^3", "check: passed", "baseline (Bezier"):
        assert text in out
    cols = _read(out_csv)
    assert list(cols) == ["t", "x", "z", "blade_angle", "depth", "fill", "F_T", "F_N"]
    path = load_path_csv(out_csv)  # the CSV is a valid path for `wheelloader predict`
    assert path.t[0] == 0.0 and np.all(np.diff(path.t) > 0)
    summary = json.loads((tmp_path / "plan.summary.json").read_text())
    assert summary["ok"] is True
    assert summary["plan"]["check"]["ok"] is True and summary["plan"]["check"]["failures"] == []
    assert summary["pile"] == "trapezoid" and summary["pareto"] == []
    # the summary's energy and fill are the NumPy re-simulation of the written path, recomputed independently
    soil = json.loads(params.read_text())["soil"]
    from wheelloader.estimator import Bucket, as_soil

    sim = path_energy(path, as_soil(soil), Pile.trapezoid(), Bucket())
    assert summary["plan"]["energy_J"] == pytest.approx(sim["energy"], rel=1e-6)
    assert summary["plan"]["fill_m3"] == pytest.approx(sim["fill"], rel=1e-6)
    assert summary["plan"]["energy_per_m3_J"] == pytest.approx(sim["energy"] / sim["fill"], rel=1e-6)
    assert np.allclose(cols["F_T"], sim["forces"].tangential) and np.allclose(cols["F_N"], sim["forces"].normal)
    assert 0.0 < summary["plan"]["fill_fraction"] <= 1.0
    assert summary["baseline"]["name"] == "Bezier" and summary["baseline"]["energy_J"] > 0.0
    assert plot.read_bytes()[:8] == PNG_MAGIC


def test_plan_pareto_on_slope_pile(tmp_path, capsys):
    out_csv, plot = tmp_path / "p.csv", tmp_path / "p.png"
    code = main(["plan", "sand", "--pile", "ideal_slope", "--energy-weight", "0.05", "--pareto", "--weights",
                 "0.01,0.2", "-o", str(out_csv), "--plot", str(plot)])
    out = capsys.readouterr().out
    summary = json.loads((tmp_path / "p.summary.json").read_text())
    assert code == (0 if summary["ok"] else 1)
    assert summary["energy_weight_per_kJ"] == 0.05 and summary["pile"] == "ideal_slope"
    points = summary["pareto"]
    assert [p["energy_weight"] for p in points] == [0.01, 0.2]
    for p in points:
        assert set(p) >= {"fill", "fill_fraction", "energy", "energy_per_m3", "status", "ok", "check_ok",
                          "failures", "solve_time", "pareto_optimal"}
        assert p["fill"] >= 0.0 and p["energy"] >= 0.0 and p["solve_time"] > 0.0
        assert p["ok"] == (p["solver_ok"] and p["check_ok"])
    assert points[1]["warm_started"] is True
    assert "Pareto sweep over 2 weights" in out
    assert plot.read_bytes()[:8] == PNG_MAGIC


def test_refuses_to_overwrite_without_force(tmp_path, capsys):
    out_csv = tmp_path / "plan.csv"
    out_csv.write_text("keep me\n")
    assert main(["plan", "gravel", "-o", str(out_csv)]) == 2
    assert "exists; pass --force" in capsys.readouterr().err
    assert out_csv.read_text() == "keep me\n"
    assert not (tmp_path / "plan.summary.json").exists()
    # an existing summary or figure is protected too
    out_csv.unlink()
    (tmp_path / "plan.summary.json").write_text("{}")
    assert main(["plan", "gravel", "-o", str(out_csv)]) == 2
    assert not out_csv.exists()
    (tmp_path / "plan.summary.json").unlink()
    (tmp_path / "fig.png").write_text("old")
    assert main(["plan", "gravel", "-o", str(out_csv), "--plot", str(tmp_path / "fig.png")]) == 2
    assert not out_csv.exists() and (tmp_path / "fig.png").read_text() == "old"
    capsys.readouterr()
    # --force replaces them
    out_csv.write_text("keep me\n")
    assert main(["plan", "gravel", "-o", str(out_csv), "--force"]) == 0
    assert _read(out_csv)["t"][0] == 0.0


@pytest.mark.parametrize("make_args, message", [
    (lambda d: [str(d / "missing.json")], "not found"),
    (lambda d: [str(d / "bad.json")], "not a valid JSON file"),
    (lambda d: ["no_such_soil"], "neither a file nor a soil preset"),
    (lambda d: [str(d / "list.json")], "expected a JSON object"),
    (lambda d: ["gravel", "--pile", "volcano"], "neither a file nor a preset"),
    (lambda d: ["gravel", "--pile", str(d / "bad.json")], "not a valid JSON file"),
    (lambda d: ["gravel", "--energy-weight", "-1"], "--energy-weight must be"),
    (lambda d: ["gravel", "--energy-weight", "nan"], "--energy-weight must be"),
    (lambda d: ["gravel", "--weights", "0.1"], "--weights needs --pareto"),
    (lambda d: ["gravel", "--pareto", "--weights", "0.1,abc"], "comma-separated numbers"),
    (lambda d: ["gravel", "--pareto", "--weights", "0.1,-2"], ">= 0"),
    (lambda d: ["gravel", "--rate", "0"], "--rate must be"),
    (lambda d: ["gravel", "-o", str(d / "x.json")], "should be a .csv file"),
    (lambda d: ["gravel", "-o", str(d / "nodir" / "plan.csv")], "does not exist"),
    (lambda d: ["gravel", "--pile", str(d / "pile.csv"), "-o", str(d / "pile.csv"), "--force"], "input files"),
    (lambda d: ["gravel", "-o", str(d / "plan.csv"), "--plot", str(d / "plan.csv"), "--force"], "given twice"),
])
def test_bad_input_is_a_clear_error(tmp_path, capsys, make_args, message):
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "list.json").write_text("[1, 2]")
    (tmp_path / "pile.csv").write_text("{}")
    (tmp_path / "params.json").write_text(json.dumps({"soil": preset("gravel").to_dict()}))
    args = make_args(tmp_path)
    out_given = "-o" in args
    assert main(["plan", *args] + ([] if out_given else ["-o", str(tmp_path / "plan.csv")])) == 2
    err = capsys.readouterr().err
    assert err.startswith("wheelloader: error: ") and message in err
    assert not (tmp_path / "plan.csv").exists() and not (tmp_path / "plan.summary.json").exists()


def test_forced_solver_failure_is_reported(tmp_path, capsys, monkeypatch):
    """IPOPT stopped after one iteration (also in the re-plan): reported, written, marked, exit status 1."""
    from dataclasses import replace

    import wheelloader.planner.next_cycle as loop

    real = loop.optimizer_for

    def one_iteration(bucket=None, loader=None, options=None):
        return real(bucket, loader, replace(options or PlannerOptions(), max_iter=1))

    monkeypatch.setattr(loop, "optimizer_for", one_iteration)
    out_csv = tmp_path / "plan.csv"
    code = main(["plan", "gravel", "-o", str(out_csv)])
    out = capsys.readouterr().out
    summary = json.loads((tmp_path / "plan.summary.json").read_text())
    assert "IPOPT did not succeed: Maximum_Iterations_Exceeded" in out
    assert summary["plan"]["solver_ok"] is False and summary["plan"]["status"] == "Maximum_Iterations_Exceeded"
    # usable only if the NumPy check passed (then said to be feasible, not proven optimal)
    assert summary["ok"] is summary["plan"]["check"]["ok"]
    if summary["ok"]:
        assert code == 0 and "not proven optimal" in out
    else:
        assert code == 1 and "NOT usable" in out and "check: FAILED" in out
        assert summary["replanned_with_wider_margins_after"]


def test_pareto_sweep_keeps_and_marks_failed_points():
    pile = Pile.trapezoid()
    points = pareto_sweep("gravel", pile, weights=(0.02, 0.1), options=PlannerOptions(max_iter=1))
    assert [p.energy_weight for p in points] == [0.02, 0.1]
    for p in points:
        assert p.status == "Maximum_Iterations_Exceeded" and not p.solver_ok
        assert p.ok == p.check_ok and (p.check_ok or p.failures)
        assert math.isfinite(p.energy) and (p.ok or not p.pareto_optimal)
    # the second solve is warm-started only from a plan that passed the check
    assert points[1].warm_started == points[0].check_ok
    assert json.dumps([p.to_dict() for p in points], allow_nan=False)


def test_mark_pareto_optimal():
    def pt(fill, energy, check_ok=True, solver_ok=True):
        return ParetoPoint(0.0, fill, fill / 0.2, energy, energy / fill, energy, "Solve_Succeeded", solver_ok,
                           check_ok, (), 0.1, 5, False)

    marked = mark_pareto_optimal([pt(0.19, 4e3), pt(0.18, 5e3), pt(0.10, 2e3), pt(0.2, 1e3, check_ok=False),
                                  pt(0.05, 1e3, solver_ok=False)])
    # a plan that failed the check never counts; a feasible one IPOPT did not converge on does
    assert [p.pareto_optimal for p in marked] == [True, False, True, False, True]


def test_importing_the_command_does_not_import_matplotlib():
    code = ("import sys, wheelloader.cli.plan, wheelloader.cli, wheelloader.plotting;"
            "wheelloader.cli.build_parser(); assert 'matplotlib' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)
