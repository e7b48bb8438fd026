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
    assert FORCE_MODELS == ("fee", "fee-payload")


def test_calibration_carries_its_model_and_predict_needs_nothing_more(log, payload_cal):
    assert payload_cal.force_model == "fee-payload"
    assert payload_cal.payload == DEFAULT_PAYLOAD
    assert payload_cal.model_options.carried_load
    pred = predict(payload_cal, log)
    removed = pred.state.carve.removed_history
    expected = kept_volume(removed, log.bucket.capacity, DEFAULT_PAYLOAD)
    np.testing.assert_allclose(pred.state.fill_volume, expected, rtol=0, atol=1e-15)
    # the carried load stays on the bucket after the tip leaves the soil; the paper's FEE drops to zero
    after = (pred.state.depth <= 0) & (np.arange(len(log)) > np.argmax(pred.state.depth > 0))
    assert np.any(after)
    assert np.all(np.hypot(pred.tangential, pred.normal)[after][-5:] > 0)
    fee = predict(payload_cal.params, log)
    assert np.all(np.hypot(fee.tangential, fee.normal)[after] == 0)


def test_predict_selects_a_model_for_bare_soil(log, payload_cal):
    pred = predict(payload_cal.params, log, force_model="fee-payload")
    assert pred.state.fill_volume[-1] == pytest.approx(kept_volume(pred.state.carve.removed_history[-1],
                                                                   log.bucket.capacity, DEFAULT_PAYLOAD))
    other = PayloadOptions(retention=0.5, heap_factor=0.4, sharpness=3.0)
    assert predict(payload_cal, log, payload=other).state.fill_volume[-1] < pred.state.fill_volume[-1]


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
