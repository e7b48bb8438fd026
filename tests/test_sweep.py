"""The sweep runner without Ray (serial mode), the --ray modes, and the promise that the core install never
imports Ray. The Ray-backed runs are in tests/test_sweep_ray.py."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from wheelloader.estimator import CycleLog, ParameterError
from wheelloader.ray_mode import add_ray_arguments, parse_ray_mode
from wheelloader.sweep import SweepError, Unit, run_sweep


def square(x: int) -> int:
    return x * x


def fail_on(x: int, bad: int) -> int:
    if x == bad:
        raise RuntimeError(f"unit {x} is broken")
    return x


def fail_first_time(x: int, marker: str) -> int:
    """Raises on its first call (a file marks that it ran), succeeds on the retry."""
    path = Path(marker)
    if not path.exists():
        path.write_text("tried")
        raise OSError("transient failure")
    return x + 100


def test_serial_results_in_submission_order_with_progress():
    lines: list[str] = []
    seen: list[tuple[int, int]] = []
    units = [Unit(square, {"x": k}, label=f"square {k}") for k in range(5)]
    result = run_sweep(units, "off", progress=lines.append, on_result=lambda k, v: seen.append((k, v)),
                       describe=lambda v: f"value {v}")
    assert result.values == [0, 1, 4, 9, 16] and result.ok and result.failures == []
    assert seen == [(k, k * k) for k in range(5)]
    assert len(lines) == 5 and lines[0].startswith("[1/5] square 0: done") and "value 0" in lines[0]
    assert "ETA" in lines[0] and lines[-1].endswith("ETA done")
    assert result.summary()["units"] == 5 and result.summary()["mode"] == "off"
    assert all(s is not None and s >= 0.0 for s in result.unit_seconds)


def test_a_failing_unit_is_retried_once_then_reported_never_lost(tmp_path):
    lines: list[str] = []
    units = [Unit(fail_on, {"x": k, "bad": 2}, label=f"unit {k}") for k in range(4)]
    units.append(Unit(fail_first_time, {"x": 7, "marker": str(tmp_path / "m")}, label="flaky"))
    result = run_sweep(units, "off", progress=lines.append)
    assert result.values == [0, 1, None, 3, 107]
    assert [f.index for f in result.failures] == [2]
    failure = result.failures[0]
    assert failure.attempts == 2 and failure.label == "unit 2" and "RuntimeError: unit 2 is broken" in failure.error
    assert "fail_on" in failure.traceback
    assert sorted(result.retried) == [2, 4]
    assert any("flaky: attempt 1 failed (OSError: transient failure); retrying" in line for line in lines)
    assert any("FAILED after 2 attempts" in line for line in lines)
    with pytest.raises(SweepError, match=r"1 of 5 sweep units failed: unit 2 \(unit 2\) failed 2x"):
        result.values_or_raise()
    assert run_sweep(units[:2], "off", retries=0).values == [0, 1]


def test_bad_input_names_what_is_wrong():
    with pytest.raises(ParameterError, match="must be a wheelloader.sweep.Unit"):
        run_sweep([square], "off")
    with pytest.raises(ParameterError, match="callable"):
        Unit(42)
    with pytest.raises(ParameterError, match="num_cpus"):
        Unit(square, {"x": 1}, num_cpus=0)
    with pytest.raises(ParameterError, match="retries"):
        run_sweep([], "off", retries=-1)
    with pytest.raises(ParameterError, match="--ray must be"):
        run_sweep([], "nowhere")


@pytest.mark.parametrize(("text", "mode"), [("off", "off"), ("LOCAL", "local"), ("auto", "auto"),
                                            ("ray://head:10001", "ray://head:10001"),
                                            ("10.0.0.1:6379", "10.0.0.1:6379")])
def test_ray_modes(text, mode):
    assert parse_ray_mode(text) == mode


def test_ray_option_rejects_nonsense():
    parser = argparse.ArgumentParser()
    add_ray_arguments(parser)
    assert parser.parse_args(["--ray", "off"]).ray == "off"
    with pytest.raises(SystemExit):
        parser.parse_args(["--ray", "cluster"])


def test_core_install_never_imports_ray():
    """Importing the package, the envs, the loop, the runner (serial run included) and the CLI's help
    leaves Ray unimported (Ray is an optional extra)."""
    code = (
        "import sys, contextlib, io\n"
        "import wheelloader, wheelloader.envs, wheelloader.adaptation, wheelloader.sweep, wheelloader.cli\n"
        "import wheelloader.references.dem, wheelloader.references.mpm.generate\n"
        "import gymnasium as gym\n"
        "gym.make('wheelloader/BucketLoading-v0').reset(seed=0)\n"
        "wheelloader.sweep.run_sweep([wheelloader.sweep.Unit(abs, {'x': -1})], 'off')\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    for argv in (['--help'], ['dem', 'reference', '--help']):\n"
        "        try:\n"
        "            wheelloader.cli.main(argv)\n"
        "        except SystemExit:\n"
        "            pass\n"
        "print(sorted(m for m in sys.modules if m == 'ray' or m.startswith('ray.')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


class _FakePlant:
    """Digs instantly: forces from the path, a pile lowered by 1 cm (as tests/test_mpm_generate.py)."""

    def __init__(self):
        self.settings = SimpleNamespace(resolution=0.02)

    def dig(self, path, pile, soil, *, seed=0):
        n = len(path)
        return CycleLog(path, np.full(n, 100.0), np.full(n, 50.0), pile, fill_volume=np.linspace(0, 0.1, n),
                        pile_after=pile.with_heights(pile.heights - 0.01),
                        metadata={"seed": seed, "resolution": 0.02, "wall_s": 1.0, "particles": 10})


def test_mpm_generator_runs_cases_through_the_sweep_and_resumes(tmp_path, monkeypatch):
    from wheelloader.references.mpm import generate

    monkeypatch.setattr(generate, "_process_plant", lambda resolution, threads: _FakePlant())
    argv = ["--out", str(tmp_path), "--only", "gravel_dual", "gravel_path1", "--ray", "off"]
    assert generate.main(argv) == 0
    names = [e["name"] for e in json.loads((tmp_path / "manifest.json").read_text())["cycles"]]
    assert names == ["gravel_path1", "gravel_dual_cycle1", "gravel_dual_cycle2"]
    first = CycleLog.load(tmp_path / "gravel_dual_cycle1.csv")
    assert first.metadata["copied_from"] == "gravel_path1.csv"  # the dual pair ran after path 1 was written
    progress = (tmp_path / "progress.log").read_text()
    assert "[1/1] gravel_path1: done" in progress and "[1/1] gravel_dual: done" in progress
    assert generate.main(argv) == 0  # resumed: both done, nothing dug
    assert progress.count("start (gravel") == 2
    log = (tmp_path / "progress.log").read_text()
    assert "gravel_path1: done, skipped" in log and "gravel_dual: done, skipped" in log


def test_mpm_generator_reports_a_failed_case_and_keeps_the_others(tmp_path, monkeypatch):
    from wheelloader.references.mpm import generate

    class Broken(_FakePlant):
        def dig(self, path, pile, soil, *, seed=0):
            if soil == "dirt":
                raise RuntimeError("solver diverged")
            return super().dig(path, pile, soil, seed=seed)

    monkeypatch.setattr(generate, "_process_plant", lambda resolution, threads: Broken())
    assert generate.main(["--out", str(tmp_path), "--only", "dirt_path1", "sand_path1", "--ray", "off"]) == 1
    log = (tmp_path / "progress.log").read_text()
    assert "FAILED unit 0 (dirt_path1) failed 2x: RuntimeError: solver diverged" in log
    assert (tmp_path / "sand_path1.csv").exists() and not (tmp_path / "dirt_path1.csv").exists()


def _fake_reference_run(case, cache_dir=None, work_dir=None, progress=None):
    """Stands in for a Yade run of ``case``: one tiny cycle log per path, its raw record and manifest entry."""
    from wheelloader.estimator import Pile, paper_paths
    from wheelloader.references.dem import ReferenceRun

    if case.config.soil == "dirt":
        raise RuntimeError("yade crashed")
    logs, raws, entries = [], [], []
    for i, stem in enumerate(case.file_stems()):
        path = paper_paths()[0]
        n = len(path)
        logs.append(CycleLog(path, np.full(n, 10.0), np.full(n, 5.0), Pile.trapezoid(),
                             fill_volume=np.zeros(n), metadata={"name": stem}))
        raws.append("t,Fx,Fz,contacts\n0,0,0,0\n")
        entries.append({"name": stem, "case": case.name, "csv": f"{stem}.csv", "raw_csv": f"raw/{stem}.csv",
                        "cycle": i + 1})
    return ReferenceRun(case, tuple(logs), tuple(raws), tuple(entries))


def test_dem_reference_command_runs_cases_through_the_sweep(tmp_path, monkeypatch, capsys):
    import wheelloader.references.dem as dem
    from wheelloader.cli import main

    monkeypatch.setattr(dem, "run_reference", _fake_reference_run)
    monkeypatch.setattr("wheelloader.references.dem.runner.find_yade", lambda: "yade")  # the fake needs no Yade
    argv = ["dem", "reference", "--out", str(tmp_path), "--ray", "off", "--only"]
    assert main([*argv, "gravel_path1", "gravel_dual"]) == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert [e["name"] for e in manifest["cycles"]] == ["gravel_path1", "gravel_dual_cycle1", "gravel_dual_cycle2"]
    assert (tmp_path / "raw" / "gravel_dual_cycle2.csv").read_text().startswith("t,Fx,Fz")
    assert CycleLog.load(tmp_path / "gravel_path1.csv").metadata["name"] == "gravel_path1"
    assert "[2/2] gravel_dual" in capsys.readouterr().out
    # a failing case is retried once, reported, and does not stop the others; exit status 1
    assert main([*argv, "dirt_path1", "gravel_path2"]) == 1
    err = capsys.readouterr().err
    assert "dirt_path1" in err and "RuntimeError: yade crashed" in err and "1 of 2 cases failed" in err
    assert (tmp_path / "gravel_path2.csv").exists() and not (tmp_path / "dirt_path1.csv").exists()
