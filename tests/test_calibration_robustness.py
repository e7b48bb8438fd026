"""Calibration on random and degenerate cycles: no crash, strict JSON (issue #13, items 1 and 7)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wheelloader.cli import main
from wheelloader.estimator import CalibrationError, CalibrationOptions, CycleLog, calibrate, synthetic_cycle
from wheelloader.estimator.synthetic import random_bezier_path, random_soil


def _variant(cycle: CycleLog, tangential, normal) -> CycleLog:
    return CycleLog(cycle.path, tangential, normal, cycle.pile, cycle.bucket, fill_volume=cycle.fill_volume)


def _random_cycles_fitted(count: int) -> int:
    """Calibrate ``count`` random in-bounds soils and paths, some scaled x10 or with swapped F_T/F_N columns
    (7 of 150 crashed); every summary and JSON report is written. Returns how many were fitted (a clear refusal,
    e.g. of a path that barely enters the soil, is not a crash).

    Every fourth cycle runs with the default settings, the others with a coarser grid and one start (the
    crash was in the report after the fit, which every setting reaches), to keep the suite's time down.
    """
    rng = np.random.default_rng(2013)
    fitted = 0
    for i in range(count):
        cycle = synthetic_cycle(random_soil(rng), random_bezier_path(rng), noise=float(rng.uniform(0.0, 0.2)),
                                seed=rng)
        if i % 4 == 1:
            cycle = _variant(cycle, 10.0 * cycle.tangential, 10.0 * cycle.normal)
        elif i % 4 == 2:
            cycle = _variant(cycle, cycle.normal, cycle.tangential)
        cheap = {} if i % 4 == 3 else {"grid": (5, 5, 4), "n_starts": 1}
        try:
            cal = calibrate(cycle, options=CalibrationOptions(**cheap))
        except CalibrationError:
            continue
        fitted += 1
        assert isinstance(cal.summary(), str)
        json.dumps(cal.to_dict(), allow_nan=False, default=float)
    return fitted


def test_random_cycles_calibrate_and_summarise():
    """The slow test's first 24 cycles (each kind six times; all 24 fitted when this was written)."""
    assert _random_cycles_fitted(24) >= 22


@pytest.mark.slow
def test_200_random_cycles_calibrate_and_summarise():
    assert _random_cycles_fitted(200) >= 190


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


# ------------------------------------------------------------------ fit verdict (issue #13, item 7)
def _degenerate_cycles() -> dict[str, CycleLog]:
    """The eight kinds of data that cannot determine the soil, on the default gravel path."""
    base = synthetic_cycle("gravel", noise=0.05, seed=0)
    n = len(base)
    rng = np.random.default_rng(7)
    peak = float(np.max(np.hypot(base.tangential, base.normal)))
    short = synthetic_cycle("gravel", random_bezier_path(np.random.default_rng(3)), noise=0.05, seed=1)
    keep = np.flatnonzero(short.contact_state().depth > 0.0)[:30]  # 30 samples in soil, then the log ends
    cut = slice(0, int(keep[-1]) + 1)
    from wheelloader.estimator import BucketPath

    short_path = BucketPath(short.path.t[cut], short.path.x[cut], short.path.z[cut], short.path.blade_angle[cut])
    return {
        "all zero": _variant(base, np.zeros(n), np.zeros(n)),
        "near zero": _variant(base, 1e-6 * base.tangential, 1e-6 * base.normal),
        "constant": _variant(base, np.full(n, 2e4), np.full(n, 3e4)),
        "1e30": _variant(base, 1e30 * base.tangential, 1e30 * base.normal),
        "pure noise": _variant(base, np.abs(rng.normal(0.0, 0.3 * peak, n)), np.abs(rng.normal(0.0, 0.3 * peak, n))),
        "snr 0.1": synthetic_cycle("gravel", noise=10.0, seed=4),
        "x10 (parameters on bounds)": _variant(base, 10.0 * base.tangential, 10.0 * base.normal),
        "too few samples in soil": CycleLog(short_path, short.tangential[cut], short.normal[cut], short.pile,
                                            short.bucket, fill_volume=short.fill_volume[cut]),
    }


@pytest.mark.parametrize("method", ["default", "single-stage"])
def test_degenerate_data_are_not_trustworthy(method):
    for kind, cycle in _degenerate_cycles().items():
        cal = calibrate(cycle, options=CalibrationOptions(method=method, min_samples=12))
        assert not cal.trustworthy, kind
        assert cal.warnings and all(w.code and w.message for w in cal.warnings), kind
        data = cal.to_dict()["calibration"]
        assert data["trustworthy"] is False and data["warnings"], kind
        assert "NOT TRUSTWORTHY" in cal.summary(), kind


def test_degenerate_data_name_their_reason():
    expected = {"all zero": "forces_near_zero", "near zero": "forces_near_zero", "constant": "constant_forces",
                "1e30": "forces_implausible", "pure noise": "unexplained", "snr 0.1": "unexplained",
                "x10 (parameters on bounds)": "parameters_on_bounds",
                "too few samples in soil": "too_few_samples"}
    for kind, cycle in _degenerate_cycles().items():
        codes = {w.code for w in calibrate(cycle, options=CalibrationOptions(min_samples=12)).warnings}
        assert expected[kind] in codes, (kind, codes)


def test_good_synthetic_cycles_are_trustworthy():
    for name in ("gravel", "sand", "dirt", "modified_sand", "dry_sand", "lean_clay", "fat_clay"):
        for noise in (0.0, 0.05):
            cal = calibrate(synthetic_cycle(name, noise=noise, vibration=noise / 2, seed=3))
            assert cal.success and cal.trustworthy, (name, noise, [str(w) for w in cal.warnings])
    rng = np.random.default_rng(11)
    trusted = sum(calibrate(synthetic_cycle(random_soil(rng), random_bezier_path(rng), noise=0.05, seed=rng))
                  .trustworthy for _ in range(30))
    assert trusted >= 27  # about 3 % of uniform soils have two parameters at the bounds (verdict docstring)


def test_physical_warnings_name_the_parameter():
    from wheelloader.estimator import PRESET_NAMES, SoilParams, preset

    assert all(preset(name).physical_warnings() == [] for name in PRESET_NAMES)
    odd = SoilParams(1e6, 1e9, 0.0, 1.5, 0.3, 0.0, 0.0, 5.0).physical_warnings()
    assert [w.split(" ")[0] for w in odd] == ["gamma", "cohesion", "phi", "n"]


def test_method_names_and_aliases():
    from wheelloader.estimator.calibration import METHODS, canonical_method

    assert METHODS == ("varpro", "single-stage", "multi-stage")
    assert canonical_method("default") == "varpro" and canonical_method(" Multi ") == "multi-stage"
    cycle = synthetic_cycle("dirt", noise=0.0)
    assert calibrate(cycle).method == "varpro"
    assert calibrate(cycle, options=CalibrationOptions(method="default")).method == "varpro"
    with pytest.raises(CalibrationError, match="unknown calibration method"):
        calibrate(cycle, options=CalibrationOptions(method="lbfgs"))


def test_huge_filter_sigma_is_refused_at_once():
    """--sigma 1e9 with the multi-stage method tried to allocate 60 GiB (issue #13, item 5)."""
    with pytest.raises(CalibrationError, match="wider than the cycle"):
        calibrate(synthetic_cycle("dirt", noise=0.0), options=CalibrationOptions(method="multi-stage", sigma=1e9))


# ------------------------------------------------------------------ long logs (issue #13, item 4)
def test_grid_in_chunks_equals_grid_at_once(monkeypatch):
    from wheelloader.estimator import PAPER_BOUNDS
    from wheelloader.estimator.calibration import varpro_grid
    from wheelloader.estimator.calibration.fitmodel import FitData
    from wheelloader.estimator.soil_vector import vector_bounds

    cycle = synthetic_cycle("dirt", noise=0.05, seed=2)
    data = FitData.from_state(cycle.contact_state(), cycle.tangential, cycle.normal, cycle.bucket)
    lo, hi = vector_bounds(PAPER_BOUNDS, cycle.bucket.edge_thickness)
    axes = (np.linspace(0.0, 0.78, 5), np.linspace(0.0, 0.78, 4), np.linspace(0.11, 1.53, 3))
    whole = varpro_grid.projected_grid(data, lo, hi, *axes)
    monkeypatch.setattr(varpro_grid, "GRID_CHUNK_ELEMENTS", 3 * len(data))  # three (phi, delta) pairs per chunk
    chunked = varpro_grid.projected_grid(data, lo, hi, *axes)
    np.testing.assert_allclose(chunked[0], whole[0], rtol=1e-9)
    np.testing.assert_allclose(chunked[1], whole[1], rtol=1e-7, atol=1e-6)


def test_long_logs_are_searched_and_fitted_on_a_uniform_subsample(monkeypatch, caplog):
    """Above the limits the grid and then the whole fit use every k-th in-soil sample; noise-free data still
    give the exact soil, and the decimation is reported (settings and a log record)."""
    from wheelloader.estimator import preset
    from wheelloader.estimator.calibration import api, varpro

    cycle = synthetic_cycle("lean_clay", noise=0.0)
    full = calibrate(cycle)
    monkeypatch.setattr(varpro, "GRID_MAX_SAMPLES", 60)
    grid_sub = calibrate(cycle)
    assert "decimation" not in grid_sub.settings
    assert grid_sub.params.gamma == pytest.approx(preset("lean_clay").gamma, rel=1e-6)
    assert grid_sub.cost == pytest.approx(full.cost, abs=1e-6 * max(full.cost, 1.0))
    monkeypatch.setattr(api, "MAX_FIT_SAMPLES", 100)
    with caplog.at_level("WARNING"):
        sub = calibrate(cycle)
    stride = sub.settings["decimation"]["stride"]
    assert stride >= 2 and "MAX_FIT_SAMPLES" in caplog.text
    assert sub.quality.samples == -(-int(full.in_soil.sum()) // stride)
    assert sub.params.gamma == pytest.approx(preset("lean_clay").gamma, rel=1e-6)
    assert sub.predicted_tangential.shape == (len(cycle),)
    json.dumps(sub.to_dict(), allow_nan=False, default=float)


def test_forces_along_a_long_log_in_blocks_equal_one_evaluation(monkeypatch):
    from wheelloader.estimator.calibration import api

    cycle = synthetic_cycle("gravel", noise=0.05, seed=5)
    whole = calibrate(cycle)
    monkeypatch.setattr(api, "FORCE_CHUNK", 37)
    blocks = calibrate(cycle)
    np.testing.assert_array_equal(blocks.predicted_tangential, whole.predicted_tangential)
    np.testing.assert_array_equal(blocks.predicted_normal, whole.predicted_normal)
    assert blocks.tension_samples == whole.tension_samples


def test_public_imports_of_the_split_estimator():
    """User code keeps working after the split into the shared model and the calibration subpackage (#14)."""
    import wheelloader.estimator as est
    import wheelloader.estimator.calibration as cal

    for name in ("calibrate", "Calibration", "FitQuality", "StageResult", "METHODS", "load_params", "predict",
                 "Prediction", "Uncertainty", "CalibrationError", "FitWarning", "CalibrationOptions"):
        assert getattr(est, name) is getattr(cal, name), name
    from wheelloader.estimator.calibration import calibrate as calibrate2
    from wheelloader.estimator.calibration.varpro import fit_varpro  # noqa: F401
    from wheelloader.estimator.failure_angle import log_ngamma_slope, optimal_beta  # noqa: F401
    from wheelloader.estimator.force_model import FLAG_OUT_OF_SOIL, clamp_angles
    from wheelloader.estimator.force_model import log_ngamma_slope as slope2

    assert calibrate2 is est.calibrate and slope2 is log_ngamma_slope and FLAG_OUT_OF_SOIL == 1
    assert clamp_angles is est.force_model.clamp_angles
