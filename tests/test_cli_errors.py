"""Every error path of the command line: one ``wheelloader: error:`` line, exit status 2, before any work
starts, no traceback (#29).

The named cases are the ones found by hand; the property test drives every subcommand with generated bad
arguments. Work is replaced by a sentinel (:class:`WorkStarted`), so an argument list that is accepted stops
where the slow part would begin: each example costs milliseconds.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wheelloader.demo
import wheelloader.estimator
import wheelloader.planner
import wheelloader.references.dem
import wheelloader.sweep
from wheelloader.cli import main
from wheelloader.cli.staging import LOCK_SUFFIX, STAGE_PREFIX
from wheelloader.estimator import paper_paths, preset, save_path_csv, synthetic_cycle

REPO = Path(__file__).resolve().parents[1]


class WorkStarted(Exception):
    """Raised where a command's slow part would start."""


def _boom(*args, **kwargs):
    raise WorkStarted


@pytest.fixture()
def no_work(monkeypatch):
    for module, name in ((wheelloader.demo, "run_demo"), (wheelloader.estimator, "calibrate"),
                         (wheelloader.estimator, "predict"), (wheelloader.planner, "optimizer_for"),
                         (wheelloader.planner, "plan_next_cycle"), (wheelloader.references.dem, "sanity_report"),
                         (wheelloader.references.dem, "run_scenario"), (wheelloader.sweep, "run_sweep")):
        monkeypatch.setattr(module, name, _boom, raising=False)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("error-inputs")
    synthetic_cycle("gravel", noise=0.0).save(d / "log.csv")
    save_path_csv(paper_paths()[1], d / "path.csv")
    (d / "params.json").write_text(json.dumps({"soil": preset("gravel").to_dict()}))
    (d / "nested.json").write_text("[" * 100_000 + "]" * 100_000)
    (d / "binary.bin").write_bytes(bytes(range(256)) * 4)
    (d / "empty.csv").write_text("")
    (d / "folder").mkdir()
    os.mkfifo(d / "fifo.csv")
    shutil.copy(d / "log.json", d / "fifo.json")
    shutil.copy(d / "nested.json", d / "nestedlog.json")
    shutil.copy(d / "log.csv", d / "nestedlog.csv")
    return d


def _one_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("wheelloader: error: "), err
    return lines[0]


# ------------------------------------------------------------------ the cases found by hand
def test_dem_sanity_on_the_mpm_set_is_one_error_line(tmp_path, capsys, no_work):
    code = main(["dem", "sanity", "--data", str(REPO / "data" / "mpm"), "--json", str(tmp_path / "s.json")])
    assert code == 2 and "not a DEM reference set" in _one_error(capsys)
    assert not (tmp_path / "s.json").exists()


@pytest.mark.skipif(shutil.which(os.environ.get("WHEELLOADER_YADE", "yade")) is not None, reason="Yade installed")
@pytest.mark.parametrize("argv", [["dem", "reference", "--only", "gravel_path1", "--ray", "off"],
                                  ["dem", "cycle"]])
def test_dem_runs_without_yade_are_one_error_line_before_any_work(tmp_path, capsys, argv):
    out = tmp_path / "out"
    assert main([*argv, "--out", str(out)]) == 2
    assert "Yade" in _one_error(capsys)
    assert not out.exists()


@pytest.mark.parametrize("argv, message", [
    (["--seed", "-1"], "--seed must be"),
    (["--seed", str(2**32)], "--seed must be"),
    (["--resolution", "0.03"], "needs --plant mpm"),
    (["--plant", "mpm", "--mpc"], "--mpc needs"),
    (["--cycles", "0"], "--cycles must be"),
    (["--window", "0"], "--window must be"),
    (["--jobs", "0"], "--jobs must be"),
    (["--jobs", "2", "--mpc"], "--jobs above 1 needs"),
    (["--jobs", "2", "--no-planner"], "--jobs above 1 needs"),
])
def test_bad_demo_options_are_refused_before_any_work(tmp_path, capsys, no_work, argv, message):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), *argv]) == 2
    assert message in _one_error(capsys)
    assert list(tmp_path.iterdir()) == []


def test_demo_on_the_mpm_plant_without_its_extra_is_refused_before_any_work(tmp_path, capsys, no_work,
                                                                             monkeypatch):
    monkeypatch.setitem(sys.modules, "taichi", None)  # import taichi now raises ImportError
    assert main(["demo", "--plant", "mpm", "-o", str(tmp_path / "demo")]) == 2
    assert "mpm extra" in _one_error(capsys)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("argv", [
    ["plan", "{d}/nested.json", "-o", "{o}/p.csv"],
    ["plan", "gravel", "--pile", "{d}/nested.json", "-o", "{o}/p.csv"],
    ["predict", "{d}/nested.json", "{d}/path.csv", "-o", "{o}/f.csv"],
    ["calibrate", "{d}/log.csv", "--initial", "{d}/nested.json", "-o", "{o}/p.json"],
    ["calibrate", "{d}/nestedlog.csv", "-o", "{o}/p.json"],
])
def test_deeply_nested_json_is_one_error_line(tmp_path, files, capsys, no_work, argv):
    assert main([a.format(d=files, o=tmp_path) for a in argv]) == 2
    assert "nested too deeply" in _one_error(capsys)


def test_an_unwritable_output_directory_is_refused_before_the_fit(files, capsys, no_work):
    assert main(["calibrate", str(files / "log.csv"), "-o", "/proc/params.json"]) == 2
    assert "/proc" in _one_error(capsys)


def test_usage_errors_are_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["demo", "--cycles", "two"])
    assert exc.value.code == 2
    assert "--cycles" in _one_error(capsys)


# ------------------------------------------------------------------ the property
BAD_VALUES = ["-1", "0", "nan", "inf", "-inf", "1e309", "99999999999999999999999", "", " ", "abc", "0.1,x",
              "{d}/folder", "{d}/missing.json", "{d}/fifo.csv", "{d}/nested.json", "{d}/binary.bin",
              "{d}/empty.csv", "/proc/x.json", "/dev/null", "{repo}/data/reference", "{repo}/data/mpm/manifest.json"]

COMMANDS: dict[str, tuple[list[str], list[str]]] = {
    # subcommand: (a valid argument list, the options and positionals ("@k") to corrupt)
    "demo": (["demo", "-o", "{o}/demo", "--cycles", "2"],
             ["--cycles", "--seed", "--seeds", "--window", "--plant", "--resolution", "-o", "--no-planner", "--mpc"]),
    "calibrate": (["calibrate", "{d}/log.csv", "-o", "{o}/p.json"],
                  ["@1", "--forgetting", "--method", "--initial", "--sigma", "-o", "--plot", "--compare"]),
    "predict": (["predict", "{d}/params.json", "{d}/path.csv", "-o", "{o}/f.csv"],
                ["@1", "@2", "-o", "--pile", "--plot", "--band"]),
    "plan": (["plan", "{d}/params.json", "-o", "{o}/p.csv"],
             ["@1", "--pile", "--energy-weight", "--weights", "--rate", "--max-time", "-o", "--plot", "--pareto"]),
    "dem sanity": (["dem", "sanity", "--data", "{repo}/data/reference", "--json", "{o}/s.json"], ["--data", "--json"]),
    "dem reference": (["dem", "reference", "--out", "{o}/ref", "--ray", "off"],
                      ["--only", "--out", "--cache-dir", "--ray", "--ray-cpus"]),
    "dem cycle": (["dem", "cycle", "--out", "{o}/cyc"],
                  ["--soil", "--path", "--scale", "--slab-width", "--radius", "--young", "--bulk-density", "--seed",
                   "--threads"]),
}


def _corrupt(argv: list[str], option: str, value: str) -> list[str]:
    if option.startswith("@"):
        argv = list(argv)
        argv[int(option[1:]) + (argv[0] == "dem")] = value
        return argv
    return [*argv, option, value]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(command=st.sampled_from(sorted(COMMANDS)), data=st.data())
def test_bad_arguments_never_give_a_traceback(files, tmp_path_factory, capsys, no_work, command, data):
    base, options = COMMANDS[command]
    out = tmp_path_factory.mktemp("out")
    argv = [a.format(d=files, o=out, repo=REPO) for a in base]
    for _ in range(data.draw(st.integers(1, 2))):
        option = data.draw(st.sampled_from(options))
        bad = [v.format(d=files, o=out, repo=REPO) for v in BAD_VALUES]
        value = data.draw(st.sampled_from(bad) | st.text(max_size=8).filter(lambda s: "\x00" not in s))
        argv = _corrupt(argv, option, value)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: a usage error
        code = exc.code
    except WorkStarted:  # accepted: the slow part would start here
        code = None
    err = capsys.readouterr().err
    assert "Traceback" not in err, (argv, err)
    if code is not None:
        assert code in (0, 2), (argv, code, err)
        if code == 2:
            assert err.strip().splitlines()[-1].startswith("wheelloader: error: "), (argv, err)
    leftovers = [p.name for p in out.iterdir() if p.name.startswith(STAGE_PREFIX) or p.name.endswith(LOCK_SUFFIX)]
    assert not leftovers, argv
