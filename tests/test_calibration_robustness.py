"""Calibration on random and degenerate cycles: no crash, strict JSON (issue #13, items 1 and 7)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wheelloader.cli import main
from wheelloader.estimator import CalibrationError, CycleLog, calibrate, synthetic_cycle
from wheelloader.estimator.synthetic import random_bezier_path, random_soil


def _variant(cycle: CycleLog, tangential, normal) -> CycleLog:
    return CycleLog(cycle.path, tangential, normal, cycle.pile, cycle.bucket, fill_volume=cycle.fill_volume)


def test_200_random_cycles_calibrate_and_summarise():
    """Random in-bounds soils and paths, some scaled x10 or with swapped F_T/F_N columns (7 of 150 crashed)."""
    rng = np.random.default_rng(2013)
    fitted = 0
    for i in range(200):
        cycle = synthetic_cycle(random_soil(rng), random_bezier_path(rng), noise=float(rng.uniform(0.0, 0.2)),
                                seed=rng)
        if i % 4 == 1:
            cycle = _variant(cycle, 10.0 * cycle.tangential, 10.0 * cycle.normal)
        elif i % 4 == 2:
            cycle = _variant(cycle, cycle.normal, cycle.tangential)
        try:
            cal = calibrate(cycle)
        except CalibrationError:
            continue  # a clear refusal (e.g. a path that barely enters the soil) is not a crash
        fitted += 1
        assert isinstance(cal.summary(), str)
        json.dumps(cal.to_dict(), allow_nan=False, default=float)
    assert fitted >= 190


def test_cli_calibrate_survives_scaled_forces(tmp_path, capsys):
    """The issue's reproduction: F_T, F_N of a gravel cycle times 10 (describe() formatted None)."""
    base = synthetic_cycle("gravel", noise=0.0, seed=0)
    log = tmp_path / "x10.csv"
    _variant(base, 10.0 * base.tangential, 10.0 * base.normal).save(log)
    out = tmp_path / "p.json"
    assert main(["calibrate", str(log), "-o", str(out)]) == 0
    json.loads(out.read_text())
    assert "identifiability" in capsys.readouterr().out


@pytest.mark.parametrize("method", ["default", "single-stage", "multi-stage"])
def test_all_zero_forces_write_strict_json(tmp_path, method):
    """All-zero forces: the result file is strict JSON (no Infinity) for every method."""
    base = synthetic_cycle("gravel", noise=0.0, seed=0)
    log = tmp_path / "zero.csv"
    _variant(base, np.zeros(len(base)), np.zeros(len(base))).save(log)
    out = tmp_path / "p.json"
    main(["calibrate", str(log), "-o", str(out), "--method", method])
    text = out.read_text()
    assert "Infinity" not in text and "NaN" not in text
    json.loads(text, parse_constant=lambda name: pytest.fail(f"non-standard JSON constant {name}"))
