"""Fit only what a cycle identifies: Sobol indices (SALib, optional), HeldPrior, the band's scale."""

from __future__ import annotations

import importlib.util
import math
import os
import sys

import numpy as np
import pytest

from wheelloader.estimator import preset
from wheelloader.estimator.calibration import CalibrationOptions, HeldPrior, calibrate, predict
from wheelloader.estimator.errors import CalibrationError
from wheelloader.estimator.soil_vector import soil_vector
from wheelloader.estimator.synthetic import synthetic_cycle

HAVE_SALIB = importlib.util.find_spec("SALib") is not None


def _need_salib():
    if not HAVE_SALIB:
        if os.environ.get("WHEELLOADER_REQUIRE_MODEL") == "1":
            pytest.fail("WHEELLOADER_REQUIRE_MODEL=1 but SALib (the model extra) is not installed")
        pytest.skip("SALib not installed: pip install 'wheelloader[model]'")


@pytest.fixture(scope="module")
def cycle():
    return synthetic_cycle("gravel", noise=0.02, seed=3)


def test_sobol_indices_are_shares_and_a_frozen_parameter_has_none(cycle):
    _need_salib()
    from wheelloader.estimator.calibration.sensitivity import SOBOL_RANGES, identifiable, sobol_indices

    state = cycle.contact_state()
    ranges = dict(SOBOL_RANGES)
    ranges["n"] = (1.2, 1.2 + 1e-9)  # n cannot move the force over a range of 1e-9
    res = sobol_indices(state, cycle.bucket, ranges=ranges, base=64, points=12, seed=1)
    assert res.samples == 64 * (len(ranges) + 2)
    assert abs(res.total["n"]) < 1e-3 and abs(res.first["n"]) < 1e-3
    assert "n" not in identifiable(res)
    assert all(-0.1 <= v <= 1.2 for v in (*res.first.values(), *res.total.values()))
    # the friction angles rule the in-soil force of a cohesionless cut; the total index is at least the first
    assert res.total["delta"] > 0.2 and res.total["phi"] > 0.05
    assert sum(res.first.values()) <= 1.1
    assert all(res.total[k] >= res.first[k] - 2 * res.first_conf[k] - 0.05 for k in res.names)
    again = sobol_indices(state, cycle.bucket, ranges=ranges, base=64, points=12, seed=1)
    assert again.total == res.total  # seeded: the same indices


def test_sobol_of_two_paths_joined_and_bad_inputs(cycle):
    _need_salib()
    from wheelloader.estimator.calibration.sensitivity import sobol_indices
    from wheelloader.estimator.errors import ParameterError

    state = cycle.contact_state()
    ranges = {"phi": (0.5, 0.75), "delta": (0.3, 0.6)}
    one = sobol_indices(state, cycle.bucket, ranges=ranges, base=32, points=8)
    two = sobol_indices([state, state], cycle.bucket, ranges=ranges, base=32, points=8)
    assert two.points == 2 * one.points
    assert two.total == pytest.approx(one.total, abs=1e-9)  # the same path twice: the same shares
    with pytest.raises(ParameterError, match="power of 2"):
        sobol_indices(state, cycle.bucket, ranges=ranges, base=30)
    with pytest.raises(ParameterError, match="unknown parameter"):
        sobol_indices(state, cycle.bucket, ranges={"k_c": (0.0, 1.0)}, base=32)


def test_sobol_without_salib_says_how_to_install(cycle, monkeypatch):
    from wheelloader.estimator.calibration.sensitivity import sobol_indices

    monkeypatch.setitem(sys.modules, "SALib", None)
    monkeypatch.setitem(sys.modules, "SALib.analyze", None)
    monkeypatch.setitem(sys.modules, "SALib.sample", None)
    with pytest.raises(ImportError, match=r"wheelloader\[model\]"):
        sobol_indices(cycle.contact_state(), cycle.bucket, base=32)


def _mean(soil):
    return dict(zip(("gamma", "cohesion", "adhesion", "phi", "delta", "K", "n"),
                    soil_vector(soil, 0.02).tolist(), strict=True))


def test_held_parameters_stay_at_the_prior_and_several_cycles_free_more(cycle):
    truth = preset("gravel")
    mean = _mean(truth) | {"n": 1.0, "K": 5.0e4}
    held = HeldPrior(mean, free_one=("gamma", "cohesion", "adhesion", "phi", "delta"),
                     free_several=("gamma", "cohesion", "adhesion", "phi", "delta", "n"))
    cal = calibrate(cycle, options=CalibrationOptions(held=held))
    assert cal.params.n == pytest.approx(1.0)
    assert cal.sinkage_modulus == pytest.approx(5.0e4)
    assert cal.settings["held"]["free"] == list(held.free_one)
    other = synthetic_cycle("gravel", noise=0.02, seed=4)
    cal2 = calibrate([cycle, other], options=CalibrationOptions(held=held))
    assert cal2.sinkage_modulus == pytest.approx(5.0e4)
    assert "n" in cal2.settings["held"]["free"]
    # a held parameter with a width is a Gaussian prior: pulled toward the mean, no longer pinned on it
    soft = HeldPrior(mean, std={"n": 0.05}, free_one=held.free_one)
    cal3 = calibrate(cycle, options=CalibrationOptions(held=soft))
    assert cal3.params.n != pytest.approx(1.0, abs=1e-9)
    assert abs(cal3.params.n - 1.0) < 0.3
    assert HeldPrior.from_dict(held.to_dict()) == held


def test_held_prior_refuses_bad_settings():
    with pytest.raises(CalibrationError, match="unknown parameter"):
        HeldPrior({"n": 1.0}, free_one=("k_c",))
    with pytest.raises(CalibrationError, match="no prior mean"):
        HeldPrior({"n": 1.0}, free_one=("phi",))
    full = {"gamma": 1500.0, "cohesion": 0.0, "adhesion": 0.0, "phi": 0.7, "delta": 0.5, "K": 1e5, "n": 1.2}
    with pytest.raises(CalibrationError, match=">= 0"):
        HeldPrior(full, std={"n": -1.0})
    with pytest.raises(CalibrationError, match="finite"):
        HeldPrior(full | {"n": math.nan})
    with pytest.raises(CalibrationError, match="varpro"):
        CalibrationOptions(held=HeldPrior(full), method="multi-stage")
    with pytest.raises(CalibrationError, match="no prior"):
        CalibrationOptions(held=HeldPrior(full), prior="granular")
    with pytest.raises(CalibrationError, match="band_scale"):
        CalibrationOptions(band_scale=0.0)


def test_band_scale_widens_the_band_by_its_factor(cycle):
    cal1 = calibrate(cycle)
    cal2 = calibrate(cycle, options=CalibrationOptions(band_scale=2.0))
    b1 = predict(cal1, cycle, band=0.9).band
    b2 = predict(cal2, cycle, band=0.9).band
    np.testing.assert_allclose(b2.std_r, 2.0 * b1.std_r, rtol=1e-9)
    assert cal2.band_model.scale == 2.0 and cal1.band_model.scale == 1.0
    assert b2.coverage(np.hypot(cycle.tangential, cycle.normal)) >= b1.coverage(np.hypot(cycle.tangential,
                                                                                       cycle.normal))


def test_the_sensitivity_benchmark_frees_what_reaches_the_threshold_on_training_families():
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "wheelloader_benchmark_sensitivity", Path(__file__).resolve().parents[1] / "benchmarks" / "sensitivity.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    names = ("gamma", "cohesion", "adhesion", "phi", "delta", "K", "n")
    rows = [{"split": "train", "cycles": 1, "total": dict.fromkeys(names, 0.01) | {"phi": 0.3, "delta": v}}
            for v in (0.02, 0.5, 0.6)]
    rows.append({"split": "test", "cycles": 1, "total": dict.fromkeys(names, 0.9)})  # never used
    assert module.rule(rows, 1)["free"] == ["phi", "delta"]
    fams = module.families(Path("data/mpm"), Path("data/results"))
    assert {f["split"] for f in fams} == {"train", "validation", "test"}
    assert all(f["cycles"] == len(f["paths"]) for f in fams)
