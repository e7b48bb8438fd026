"""The opt-in carried-load term: weight and inertia of the soil in the bucket, in every copy of the model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wheelloader.estimator import Bucket, ModelOptions, Pile, default_path, preset
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.calibration.fitmodel import FIT_NAMES, FitData, soil_to_fit
from wheelloader.estimator.errors import CalibrationError, ParameterError
from wheelloader.estimator.force_model import carried_load_factors, soil_forces, soil_forces_single
from wheelloader.estimator.kinematics import contact_state
from wheelloader.estimator.synthetic import synthetic_cycle

ON = ModelOptions(carried_load=True)


def _state(acceleration=True):
    path = default_path()
    acc = np.column_stack(path.acceleration()) if acceleration else None
    return contact_state(path.x, path.z, path.blade_angle, Pile.trapezoid(), Bucket(), acceleration=acc)


def test_factors_are_the_blade_frame_weight_and_inertia():
    # a horizontal blade at rest: the load presses along -z, i.e. on F_N only
    c_t, c_n = carried_load_factors(np.array([0.0]))
    assert c_t[0] == pytest.approx(0.0) and c_n[0] == pytest.approx(1.0)
    # blade tip up at 90 deg: the weight acts along the blade (F_T)
    c_t, c_n = carried_load_factors(np.array([math.pi / 2]))
    assert c_t[0] == pytest.approx(1.0) and c_n[0] == pytest.approx(0.0, abs=1e-12)
    # accelerating up at g doubles the load; accelerating along +x (into the pile) pushes back along the blade
    c_t, c_n = carried_load_factors(np.array([0.0]), np.array([[0.0, 9.81]]))
    assert c_n[0] == pytest.approx(2.0)
    c_t, _ = carried_load_factors(np.array([0.0]), np.array([[9.81, 0.0]]))
    assert c_t[0] == pytest.approx(1.0)


def test_default_model_is_unchanged_and_the_term_adds_exactly_the_load():
    soil, state, bucket = preset("gravel"), _state(), Bucket()
    off, on = soil_forces(soil, state, bucket), soil_forces(soil, state, bucket, ON)
    c_t, c_n = carried_load_factors(state.blade_angle, state.acceleration)
    w = state.load_weight(soil.gamma)
    np.testing.assert_allclose(on.tangential - off.tangential, w * c_t, atol=1e-9)
    np.testing.assert_allclose(on.normal - off.normal, w * c_n, atol=1e-9)
    out = state.depth <= 0.0
    assert np.any(out & (w > 0)) and np.all(on.normal[out & (w > 0)] > 0.0)  # carried after the tip leaves
    assert np.array_equal(off.flags, on.flags)


def test_scalar_path_equals_vectorised_model():
    soil, state, bucket = preset("dirt"), _state(), Bucket()
    f = soil_forces(soil, state, bucket, ON)
    for i in range(0, len(state), 17):
        f_t, f_n, _, flags = soil_forces_single(soil, state.depth[i], state.rho[i], state.alpha[i],
                                                state.blade_length[i], state.load_weight(soil.gamma)[i], bucket, ON,
                                                acceleration=tuple(state.acceleration[i]))
        assert f_t == pytest.approx(f.tangential[i], rel=1e-9, abs=1e-6)
        assert f_n == pytest.approx(f.normal[i], rel=1e-9, abs=1e-6)
        assert flags == f.flags[i]


def test_fit_model_and_jacobian_with_the_term():
    state, bucket = _state(), Bucket()
    soil = preset("dirt")
    f = soil_forces(soil, state, bucket, ON)
    data = FitData.from_state(state, f.tangential, f.normal, bucket, ON)
    p = soil_to_fit(soil, bucket.edge_thickness)
    f_t, f_n, jt, jn = data.forces_and_jacobian(p)
    np.testing.assert_allclose(f_t, f.tangential[data.index], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(f_n, f.normal[data.index], rtol=1e-12, atol=1e-9)
    h = 1e-3
    up, dn = p.copy(), p.copy()
    up[0] += h
    dn[0] -= h
    fd = (np.concatenate(data.forces(up)[:2]) - np.concatenate(data.forces(dn)[:2])) / (2 * h)
    np.testing.assert_allclose(np.concatenate([jt[:, 0], jn[:, 0]]), fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(fd)))
    assert FIT_NAMES[0] == "gamma"


@pytest.mark.parametrize("soil_name", ["gravel", "lean_clay"])
def test_calibration_recovers_a_soil_with_the_carried_load(soil_name):
    log = synthetic_cycle(soil_name, noise=0.0, options=ON)
    off = calibrate(log)
    on = calibrate(log, options=CalibrationOptions(model_options=ON))
    assert on.quality.percent_r <= 0.1
    assert on.params.gamma == pytest.approx(preset(soil_name).gamma, rel=1e-3)
    assert off.quality.percent_r > on.quality.percent_r
    # the calibration remembers its model: predict() uses it without being told
    assert on.model_options == ON and off.model_options == ModelOptions()
    assert predict(on, log).quality.percent_r == pytest.approx(on.quality.percent_r, abs=1e-6)


def test_options_are_checked():
    with pytest.raises(ParameterError, match="carried_load"):
        ModelOptions(carried_load=1)
    log = synthetic_cycle("gravel", noise=0.0)
    with pytest.raises(CalibrationError, match="varpro"):
        calibrate(log, options=CalibrationOptions(method="multi-stage", model_options=ON))
    assert ON.extra_terms == ("carried_load",) and ModelOptions().extra_terms == ()


# ------------------------------------------------------------------ slip-mobilised friction
BOTH = ModelOptions(carried_load=True, slip_friction=True)


def _state_with_velocity():
    path = default_path()
    return contact_state(path.x, path.z, path.blade_angle, Pile.trapezoid(), Bucket(),
                         acceleration=np.column_stack(path.acceleration()),
                         velocity=np.column_stack(path.velocity()[:2]))


def test_slip_factor_values():
    from wheelloader.estimator.force_model import slip_factor

    th = np.zeros(4)
    vel = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, 0.0]])  # along, normal, backwards, at rest
    m = slip_factor(th, vel, 0.05)
    assert m[0] == pytest.approx(1.0) and m[3] == pytest.approx(1.0)
    assert m[1] == pytest.approx(0.05 / 1.05) and m[2] == pytest.approx(0.05 / 1.05)
    assert np.all(slip_factor(th) == 1.0)


def test_slip_friction_everywhere_alike(assert_fit_jacobian):
    soil, state, bucket = preset("dirt"), _state_with_velocity(), Bucket()
    f = soil_forces(soil, state, bucket, BOTH)
    paper = soil_forces(soil, state, bucket)
    slip_only = soil_forces(soil, state, bucket, ModelOptions(slip_friction=True))
    np.testing.assert_array_equal(slip_only.normal, paper.normal)  # friction acts along the blade only
    assert np.all(slip_only.tangential <= paper.tangential + 1e-9)  # scaled by a factor in [0, 1]
    assert np.any(np.abs(f.tangential - paper.tangential) > 1.0)
    for i in range(0, len(state), 13):
        f_t, f_n, _, _ = soil_forces_single(soil, state.depth[i], state.rho[i], state.alpha[i], state.blade_length[i],
                                            state.load_weight(soil.gamma)[i], bucket, BOTH,
                                            acceleration=tuple(state.acceleration[i]),
                                            velocity=tuple(state.velocity[i]))
        assert f_t == pytest.approx(f.tangential[i], rel=1e-9, abs=1e-6)
        assert f_n == pytest.approx(f.normal[i], rel=1e-9, abs=1e-6)
    data = FitData.from_state(state, f.tangential, f.normal, bucket, BOTH)
    p = soil_to_fit(soil, bucket.edge_thickness)
    p[2] = 800.0  # adhesion off zero for the finite differences
    assert_fit_jacobian(data, p)


def test_calibration_recovers_a_soil_with_slip_friction():
    opts = ModelOptions(slip_friction=True)
    log = synthetic_cycle("dirt", noise=0.0, options=opts)
    cal = calibrate(log, options=CalibrationOptions(model_options=opts))
    assert cal.quality.percent_r <= 0.1
    assert predict(cal, log).quality.percent_r == pytest.approx(cal.quality.percent_r, abs=1e-6)
