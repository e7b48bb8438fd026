"""The smaller items of #29, one test each (the flipped F_N column and the FIFO input are in
``test_plausibility.py`` and ``test_cli_sacred_inputs.py``)."""

from __future__ import annotations

import dataclasses
import json
import os
import re

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the env ids)
import wheelloader.planner
from wheelloader.cli import main
from wheelloader.estimator import ParameterError, Pile, predict, preset, synthetic_cycle


@pytest.fixture()
def log_csv(tmp_path):
    path = tmp_path / "log.csv"
    synthetic_cycle("gravel", noise=0.0).save(path)
    return path


def test_the_same_log_given_twice_is_refused(log_csv, tmp_path, capsys):
    os.symlink(log_csv, tmp_path / "alias.csv")
    os.symlink(log_csv.with_suffix(".json"), tmp_path / "alias.json")
    for second in (log_csv, tmp_path / "alias.csv"):
        assert main(["calibrate", str(log_csv), str(second), "-o", str(tmp_path / "p.json")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("wheelloader: error:") and "same file" in err
    assert not (tmp_path / "p.json").exists()


def test_the_log_s_own_in_soil_count_is_printed_when_the_fit_decimates(log_csv, tmp_path, capsys, monkeypatch):
    import wheelloader.estimator.calibration.api as api

    assert main(["calibrate", str(log_csv), "-o", str(tmp_path / "a.json")]) == 0
    full = int(re.search(r"(\d+) in soil", capsys.readouterr().out).group(1))
    monkeypatch.setattr(api, "MAX_FIT_SAMPLES", full // 3)
    stride = -(-full // (full // 3))
    assert main(["calibrate", str(log_csv), "-o", str(tmp_path / "b.json")]) in (0, 1)
    out = capsys.readouterr().out
    assert re.search(rf"\b{full} in soil \(every {stride}-th fitted: {-(-full // stride)}\)", out), out


def test_a_plan_that_loads_nothing_is_not_reported_as_passed(tmp_path, capsys, monkeypatch):
    """``plan_next_cycle`` refuses a plan that loads (almost) nothing even when it passes the NumPy check; the
    command said "check: passed" for it (a 1000 m pile: 0 % fill) and exited 0."""
    real = wheelloader.planner.plan_next_cycle

    def refused(*args, **kwargs):
        outcome = real(*args, **kwargs)
        return dataclasses.replace(outcome, path=None, success=False,
                                   message="IPOPT: Solve_Succeeded; the plan loads only 0% of the bucket")

    monkeypatch.setattr(wheelloader.planner, "plan_next_cycle", refused)
    code = main(["plan", "gravel", "-o", str(tmp_path / "p.csv")])
    out = capsys.readouterr().out
    assert code == 1
    assert "check: passed" not in out and "check: FAILED: IPOPT: Solve_Succeeded; the plan loads only 0%" in out
    assert json.loads((tmp_path / "p.summary.json").read_text())["ok"] is False


def test_an_iterate_kept_as_the_plan_has_its_solve_time():
    from wheelloader.planner import PlannerOptions, cycle_duration, default_start, optimizer_for

    opt = optimizer_for(options=PlannerOptions())
    pile = Pile.trapezoid()
    start = default_start(pile)
    seen = []
    opt.reset_warm_start()
    final = opt.solve(preset("gravel"), pile, start, cycle_duration(pile, start),
                      checkpoint=lambda plan: seen.append(plan) or False, checkpoint_every=5)
    assert seen and all(p.status.startswith("iterate") for p in seen)
    times = [p.solve_time for p in seen]
    assert all(t > 0.0 for t in times) and times == sorted(times) and times[-1] <= final.solve_time


def test_a_wrong_shape_action_is_a_clear_error():
    env = gym.make("wheelloader/BucketLoading-v0")
    env.reset(seed=0)
    with pytest.raises(ParameterError, match="action must be 3 numbers"):
        env.step(np.zeros(4))
    venv = gym.make_vec("wheelloader/BucketLoading-v0", num_envs=2)
    venv.reset(seed=0)
    with pytest.raises(ParameterError, match=r"actions must be 2 x 3 numbers"):
        venv.step(np.zeros(5))


def test_predict_without_parameters_is_a_clear_error():
    with pytest.raises(ParameterError, match="got NoneType"):
        predict(None, synthetic_cycle("gravel"))


@pytest.mark.parametrize("command", ["cycle", "reference", "sanity", "list"])
def test_dem_help_lists_every_option_with_text(command, capsys):
    with pytest.raises(SystemExit):
        main(["dem", command, "--help"])
    text = capsys.readouterr().out
    options = text.split("options:", 1)[1]
    entries = re.split(r"\n  (?=-)", "\n" + options.strip("\n"))
    for entry in entries[1:]:
        name, _, rest = entry.partition(" ")
        words = re.sub(r"^[A-Z_{},0-9 ]+", "", rest.strip()) if rest.strip() else ""
        assert len(words.split()) >= 3, f"dem {command} {name}: no help text"
    if command == "cycle":
        for unit in ("[m]", "[Pa]", "[kg/m^3]", "[-]"):
            assert unit in text
