"""force_model= selects the model in calibrate and predict; a Calibration carries its model."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from wheelloader.estimator import DEFAULT_PAYLOAD, FORCE_MODELS, CycleLog, PayloadOptions, calibrate, predict
from wheelloader.estimator.calibration import CalibrationOptions
from wheelloader.estimator.errors import CalibrationError, ParameterError
from wheelloader.estimator.payload import kept_volume

LOG = Path(__file__).resolve().parents[1] / "data" / "mpm" / "sand_path1.csv"


@pytest.fixture(scope="module")
def log():
    return CycleLog.load(LOG)


@pytest.fixture(scope="module")
def payload_cal(log):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate(log, options=CalibrationOptions(force_model="fee-payload", grid=(4, 4, 3), n_starts=1))


def test_names_listed():
    assert FORCE_MODELS == ("fee", "fee-payload", "fee-learned", "fee-payload-depth")


def test_calibration_carries_its_model_and_predict_needs_nothing_more(log, payload_cal):
    assert payload_cal.force_model == "fee-payload"
    assert payload_cal.payload == DEFAULT_PAYLOAD
    assert payload_cal.model_options.carried_load and not payload_cal.model_options.carried_in_soil
    pred = predict(payload_cal, log)
    removed = pred.state.carve.removed_history
    expected = kept_volume(removed, log.bucket.capacity, DEFAULT_PAYLOAD)
    np.testing.assert_allclose(pred.state.carried_volume, expected, rtol=0, atol=1e-15)
    # the surcharge keeps the FEE's carved fill
    np.testing.assert_array_equal(pred.state.fill_volume, log.contact_state(fill="model").fill_volume)
    # the carried load stays on the bucket after the tip leaves the soil; the paper's FEE drops to zero
    after = (pred.state.depth <= 0) & (np.arange(len(log)) > np.argmax(pred.state.depth > 0))
    assert np.any(after)
    assert np.all(np.hypot(pred.tangential, pred.normal)[after][-5:] > 0)
    fee = predict(payload_cal.params, log)
    assert np.all(np.hypot(fee.tangential, fee.normal)[after] == 0)


def test_predict_selects_a_model_for_bare_soil(log, payload_cal):
    pred = predict(payload_cal.params, log, force_model="fee-payload")
    assert pred.state.carried_volume[-1] == pytest.approx(kept_volume(pred.state.carve.removed_history[-1],
                                                                      log.bucket.capacity, DEFAULT_PAYLOAD))
    other = PayloadOptions(retention=0.5, heap_factor=0.4, sharpness=3.0)
    assert predict(payload_cal, log, payload=other).state.carried_volume[-1] < pred.state.carried_volume[-1]


def test_in_soil_the_payload_model_is_the_fee_with_the_carved_fill(log, payload_cal):
    """Below the contact depth the two models agree exactly; above the surface only the carried load acts."""
    pay = predict(payload_cal, log)
    fee = predict(payload_cal.params, log, fill="model", options=payload_cal.model_options.__class__())
    deep = pay.state.depth >= payload_cal.model_options.contact_depth
    assert np.count_nonzero(deep) > 50
    np.testing.assert_allclose(pay.tangential[deep], fee.tangential[deep], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(pay.normal[deep], fee.normal[deep], rtol=1e-12, atol=1e-9)
    out = pay.state.depth <= 0
    weight = payload_cal.params.gamma * 9.81 * pay.state.carried_volume[out]
    np.testing.assert_allclose(np.hypot(pay.tangential, pay.normal)[out] > 0, weight > 0)


def test_the_hand_over_is_continuous_and_the_single_sample_form_agrees():
    """The carried load ramps in as the surcharge ramps out; soil_forces_single equals soil_forces."""
    from wheelloader.estimator import Bucket
    from wheelloader.estimator.force_model import soil_forces, soil_forces_single
    from wheelloader.estimator.force_models import model_options_for
    from wheelloader.estimator.kinematics import ContactState
    from wheelloader.estimator.soil import preset
    from wheelloader.estimator.validity import ModelOptions

    opts = model_options_for("fee-payload", ModelOptions())
    soil, bucket = preset("sand"), Bucket()
    depth = np.linspace(-0.01, 0.05, 601)
    k = depth.size
    state = ContactState(np.maximum(depth, 0.0), np.full(k, 0.6), np.full(k, 0.3), np.clip(depth, 0.0, 0.4) / 0.6,
                         np.full(k, 0.3), acceleration=np.zeros((k, 2)), carried_volume=np.full(k, 0.2))
    f = soil_forces(soil, state, bucket, opts)
    assert np.max(np.abs(np.diff(f.tangential))) < 0.02 * np.max(np.abs(f.tangential))
    for i in (0, 100, 150, 200, 300, 600):
        single = soil_forces_single(soil, float(state.depth[i]), 0.6, 0.3, float(state.blade_length[i]),
                                    soil.gamma * 9.81 * 0.3, bucket, opts,
                                    carried_weight=soil.gamma * 9.81 * 0.2)
        assert single[0] == pytest.approx(f.tangential[i], rel=1e-9, abs=1e-9)
        assert single[1] == pytest.approx(f.normal[i], rel=1e-9, abs=1e-9)


def test_default_is_the_paper_model(log):
    opts = CalibrationOptions()
    assert opts.force_model == "fee" and opts.payload is None and not opts.model_options.carried_load


@pytest.mark.parametrize("kwargs, match", [
    (dict(force_model="mlp"), "force_model must be one of"),
    (dict(payload=PayloadOptions()), "fee-payload"),
    (dict(force_model="fee-payload", payload={"retention": 1}), "PayloadOptions"),
    (dict(force_model="fee-payload", method="multi-stage"), "varpro"),
])
def test_bad_selections_are_refused(kwargs, match):
    with pytest.raises(CalibrationError, match=match):
        CalibrationOptions(**kwargs)


def test_predict_refuses_an_unknown_model(log):
    with pytest.raises(ParameterError, match="force_model"):
        predict("sand", log, force_model="nope")
