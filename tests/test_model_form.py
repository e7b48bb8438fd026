"""``"fee-payload-depth"``: the wedge factor N_gamma + k (``ModelOptions.wedge_offset``) everywhere the FEE is."""

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from wheelloader.estimator import (
    DEFAULT_WEDGE_OFFSET,
    GRAVITY,
    Bucket,
    CycleLog,
    ModelOptions,
    Pile,
    calibrate,
    contact_state,
    default_path,
    predict,
    preset,
    soil_forces,
    soil_forces_single,
)
from wheelloader.estimator.calibration import CalibrationOptions
from wheelloader.estimator.calibration.fitmodel import FitData, soil_to_fit
from wheelloader.estimator.errors import ParameterError
from wheelloader.estimator.force_models import model_options_for

LOG = Path(__file__).resolve().parents[1] / "data" / "mpm" / "sand_path1.csv"


def _state():
    path, pile, bucket = default_path(), Pile.trapezoid(), Bucket()
    return contact_state(path.x, path.z, path.blade_angle, pile, bucket), bucket


def test_offset_is_checked_and_named():
    with pytest.raises(ParameterError, match="wedge_offset"):
        ModelOptions(wedge_offset=-0.1)
    assert "wedge_offset" in ModelOptions(wedge_offset=1.0).extra_terms and not ModelOptions().extra_terms
    opts = model_options_for("fee-payload-depth", ModelOptions())
    assert opts.wedge_offset == DEFAULT_WEDGE_OFFSET > 0.0 and opts.carried_load and not opts.carried_in_soil
    assert model_options_for("fee-payload", ModelOptions()).wedge_offset == 0.0  # fee-payload stays put


@pytest.mark.parametrize("soil_name", ["gravel", "dirt"])
def test_offset_adds_k_gamma_g_w_d2_along_the_fee_direction(soil_name):
    """Known answer: where eq 1 is not clamped, F(k) - F(0) = k gamma g w d^2 (sin delta, cos delta)."""
    soil = preset(soil_name)
    state, bucket = _state()
    k = 1.7
    base = soil_forces(soil, state, bucket)
    off = soil_forces(soil, state, bucket, ModelOptions(wedge_offset=k))
    d = np.maximum(state.depth, 0.0)
    added = k * soil.gamma * GRAVITY * bucket.width * d * d
    live = (base.fee_force > 0.0) & (state.depth > 0.0)
    assert live.sum() > 20
    np.testing.assert_allclose(off.normal[live] - base.normal[live], added[live] * math.cos(soil.delta), rtol=1e-9,
                               atol=1e-6)
    np.testing.assert_allclose(off.tangential[live] - base.tangential[live], added[live] * math.sin(soil.delta),
                               rtol=1e-9, atol=1e-6)
    out = state.depth <= 0.0
    assert np.all(off.tangential[out] == base.tangential[out])  # nothing out of soil


def test_single_sample_equals_the_arrays_with_the_offset():
    soil = preset("sand")
    state, bucket = _state()
    opts = ModelOptions(wedge_offset=2.0)
    arr = soil_forces(soil, state, bucket, opts)
    for i in np.linspace(0, len(state) - 1, 25).astype(int):
        f_t, f_n, _, flags = soil_forces_single(soil, float(state.depth[i]), float(state.rho[i]), float(state.alpha[i]),
                                                float(state.blade_length[i]), float(state.load_weight(soil.gamma)[i]),
                                                bucket, opts)
        assert flags == arr.flags[i]
        np.testing.assert_allclose([f_t, f_n], [arr.tangential[i], arr.normal[i]], rtol=1e-7, atol=1e-6)


def test_fit_model_is_the_force_model_with_the_offset(assert_fit_jacobian):
    soil = preset("gravel")
    state, bucket = _state()
    opts = ModelOptions(wedge_offset=2.0)
    f = soil_forces(soil, state, bucket, opts)
    data = FitData.from_state(state, f.tangential, f.normal, bucket, opts)
    p = soil_to_fit(soil, bucket.edge_thickness)
    f_t, f_n, _ = data.forces(p)
    np.testing.assert_allclose(f_t, f.tangential[data.index], rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(f_n, f.normal[data.index], rtol=1e-9, atol=1e-6)
    assert_fit_jacobian(data, p)


def test_calibration_carries_the_offset_and_predicts_its_own_fit():
    log = CycleLog.load(LOG)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(log, options=CalibrationOptions(force_model="fee-payload-depth", grid=(4, 4, 3), n_starts=1))
        base = calibrate(log, options=CalibrationOptions(force_model="fee-payload", grid=(4, 4, 3), n_starts=1))
    assert cal.force_model == "fee-payload-depth" and cal.model_options.wedge_offset == DEFAULT_WEDGE_OFFSET
    assert base.model_options.wedge_offset == 0.0
    pred = predict(cal, log)
    inside = pred.state.depth > 0.0
    np.testing.assert_allclose(pred.tangential[inside], cal.predicted_tangential[cal.in_soil], rtol=1e-6, atol=1e-3)
    # the same soil under fee-payload predicts less: the offset's share is positive in soil
    plain = predict(cal.params, log, options=base.model_options, force_model="fee-payload", payload=cal.payload)
    assert np.all(np.hypot(pred.tangential, pred.normal)[inside] >= np.hypot(plain.tangential, plain.normal)[inside]
                  - 1e-9)


def test_form_study_fitter_recovers_a_form_it_can_express():
    """``benchmarks/model_form.py``: forces made by a form (a grid point, known coefficients) are fitted back
    exactly, and an extra term's coefficient is recovered."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_model_form",
                                                  Path(__file__).resolve().parents[1] / "benchmarks" / "model_form.py")
    mf = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mf)
    mf.PHI_GRID, mf.DELTA_GRID, mf.N_GRID = np.radians([20.0, 35.0]), np.radians([15.0, 30.0]), (1.0, 1.53)
    case = mf.Case(LOG, mf.DEFAULT_PAYLOAD)
    terms = ("lift",)
    a_t, a_n = mf.columns(case, math.radians(35.0), math.radians(15.0), 1.53, terms)
    truth = np.array([1500.0, 0.0, 0.0, 4.0e5, 3000.0])
    case.y_t, case.y_n = a_t @ truth, a_n @ truth
    case.obs_r = np.hypot(case.y_t, case.y_n)
    fit = mf.fit_form([case], terms)
    assert (round(math.degrees(fit["phi"])), round(math.degrees(fit["delta"])), fit["n"]) == (35, 15, 1.53)
    np.testing.assert_allclose(fit["coefficients"], truth, rtol=1e-6, atol=1e-6 * truth.max())
    assert mf.form_error(case, fit, terms)[0] < 1e-6
