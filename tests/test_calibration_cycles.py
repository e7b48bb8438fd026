"""Calibration from several cycles: one soil fitted to all logs, forgetting factor, per-cycle report."""

from __future__ import annotations

import numpy as np
import pytest

from wheelloader.estimator import PAPER_BOUNDS, Bucket, preset
from wheelloader.estimator.calibration import CalibrationOptions, calibrate
from wheelloader.estimator.calibration.api import cycle_weights_for
from wheelloader.estimator.calibration.fitmodel import FIT_NAMES, FitData, fit_bounds, soil_to_fit
from wheelloader.estimator.errors import CalibrationError
from wheelloader.estimator.synthetic import random_bezier_path, synthetic_cycle


def _cycles(soil_name: str, count: int, noise: float = 0.0, seed: int = 3):
    rng = np.random.default_rng(seed)
    return [synthetic_cycle(soil_name, random_bezier_path(rng, name=f"p{k}"), noise=noise, seed=seed + k)
            for k in range(count)]


def test_list_of_one_log_is_bit_identical_to_the_log():
    log = synthetic_cycle("gravel", noise=0.05, seed=4)
    a, b = calibrate(log), calibrate([log])
    assert np.array_equal(a.params.to_array(), b.params.to_array())
    assert a.cost == b.cost and a.nfev == b.nfev
    assert np.array_equal(a.predicted_tangential, b.predicted_tangential)
    assert b.cycle_count == 1 and b.identifiability_by_cycles == []


@pytest.mark.parametrize("soil_name", ["gravel", "dirt"])
def test_several_noise_free_cycles_recover_the_soil(soil_name):
    cal = calibrate(_cycles(soil_name, 3))
    assert cal.success and cal.cycle_count == 3
    true = soil_to_fit(preset(soil_name), 0.02)
    est = np.array([*(getattr(cal.params, n) for n in FIT_NAMES[:5]), cal.sinkage_modulus, cal.params.n])
    lo, hi = fit_bounds(PAPER_BOUNDS, 0.02)
    rel = np.abs(est - true) / np.maximum(np.abs(true), 1e-6 * (hi - lo))
    assert np.max(rel) <= 0.01, dict(zip(FIT_NAMES, rel, strict=True))
    assert cal.quality.percent_r <= 0.1
    per = cal.settings["cycles"]["per_cycle"]
    assert [c["samples"] for c in per] == [int(np.count_nonzero(lg.contact_state().depth > 0))
                                           for lg in _cycles(soil_name, 3)]
    assert len(cal.predicted_tangential) == sum(len(lg) for lg in _cycles(soil_name, 3))


def test_joint_cost_is_not_above_the_single_cycle_fits_cost_on_all_cycles():
    """The joint fit minimises the summed cost: no single-cycle fit does better on all cycles together."""
    logs = _cycles("sand", 3, noise=0.08, seed=9)
    joint = calibrate(logs)
    parts = [FitData.from_state(lg.contact_state(), lg.tangential, lg.normal, lg.bucket) for lg in logs]
    data = FitData.concat(parts)
    for lg in logs:
        single = calibrate(lg)
        f_t, f_n, _ = data.forces(soil_to_fit(single.params, 0.02))
        cost = 0.5 * np.sum((f_t - data.y_t) ** 2) + 0.5 * np.sum((f_n - data.y_n) ** 2)
        assert joint.cost <= cost * (1 + 1e-9)


def test_identifiability_by_cycles_never_loses_information():
    """Adding a cycle adds rows to the Jacobian: no free parameter's standard error grows."""
    cal = calibrate(_cycles("dirt", 3, noise=0.05, seed=5))
    rows = cal.identifiability_by_cycles
    assert [r["cycles"] for r in rows] == [1, 2, 3]
    for name in FIT_NAMES:
        if rows[0]["status"][name] == "at bound":
            continue
        rel = [r["relative_std_errors"][name] for r in rows]
        if rel[0] is None:
            continue
        # effective noise is the same for every prefix only up to the residual std; allow 1 % slack
        assert all(b <= a * 1.01 for a, b in zip(rel, rel[1:], strict=False)), (name, rel)
    assert "what each added cycle determined" in cal.summary()


def test_forgetting_factor_weights_the_newest_cycle_most():
    assert cycle_weights_for(3, 0.5) == [0.25, 0.5, 1.0]
    assert cycle_weights_for(2) is None
    assert cycle_weights_for(2, cycle_weights=[2, 1]) == [2.0, 1.0]
    # a drifting soil: old cycles of one soil, the newest of another; forgetting pulls towards the newest
    rng = np.random.default_rng(1)
    old = [synthetic_cycle("gravel", random_bezier_path(rng), noise=0.0) for _ in range(2)]
    new = synthetic_cycle("modified_sand", random_bezier_path(rng), noise=0.0)
    plain = calibrate([*old, new])
    forget = calibrate([*old, new], options=CalibrationOptions(forgetting=0.01))
    newest = [c["settings"]["cycles"]["per_cycle"][-1]["rmse"]["F_R"][0] for c in (plain.to_dict()["calibration"],
                                                                               forget.to_dict()["calibration"])]
    assert newest[1] < 0.5 * newest[0]
    assert forget.settings["cycles"]["per_cycle"][0]["weight"] == pytest.approx(1e-4)


def test_bad_cycle_lists_are_rejected():
    log = synthetic_cycle("gravel", noise=0.0)
    with pytest.raises(CalibrationError, match="empty"):
        calibrate([])
    with pytest.raises(CalibrationError, match=r"cycle\[1\]"):
        calibrate([log, "x"])
    with pytest.raises(CalibrationError, match="varpro method only"):
        calibrate([log, log], options=CalibrationOptions(method="multi-stage"))
    with pytest.raises(CalibrationError, match="forgetting"):
        calibrate([log, log], options=CalibrationOptions(forgetting=1.5))
    with pytest.raises(CalibrationError, match="not both"):
        calibrate([log, log], options=CalibrationOptions(forgetting=0.5, cycle_weights=[1, 1]))
    with pytest.raises(CalibrationError, match="one per cycle"):
        calibrate([log, log], options=CalibrationOptions(cycle_weights=[1.0]))
    other = synthetic_cycle("gravel", bucket=Bucket(edge_thickness=0.03), noise=0.0)
    with pytest.raises(CalibrationError, match="another bucket"):
        calibrate([log, other])
