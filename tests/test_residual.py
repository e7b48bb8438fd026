"""The learned residual: a ridge that recovers a quadratic, JSON round trip, the trusted range, the log shift."""

from pathlib import Path

import numpy as np
import pytest

from wheelloader.estimator import DEFAULT_PAYLOAD, CycleLog
from wheelloader.estimator.errors import ParameterError
from wheelloader.estimator.payload import payload_contact_state
from wheelloader.estimator.residual import (
    FEATURE_NAMES,
    ResidualModel,
    corrected_log,
    features,
    fit_residual,
    force_scale,
    residual_forces,
)

LOG = Path(__file__).resolve().parents[1] / "data" / "mpm" / "sand_path1.csv"


def _quadratic(x):
    return np.column_stack([0.3 + x[:, 0] - 2.0 * x[:, 1] * x[:, 2], 0.1 * x[:, 3] ** 2 - x[:, 7]])


def test_the_ridge_recovers_a_quadratic_in_the_inputs_and_clips_outside_their_range():
    rng = np.random.default_rng(0)
    x = rng.uniform(-3.0, 3.0, size=(400, len(FEATURE_NAMES)))
    model = fit_residual([(x[:200], _quadratic(x[:200])), (x[200:], _quadratic(x[200:]))], ridge=1e-12)
    test = rng.uniform(-2.0, 2.0, size=(50, len(FEATURE_NAMES)))
    np.testing.assert_allclose(model.predict(test), _quadratic(test), atol=1e-8)
    far = np.full((1, len(FEATURE_NAMES)), 100.0)
    np.testing.assert_allclose(model.predict(far), model.predict(model.high[None, :]))


def test_json_round_trip_and_the_trusted_range():
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 1.0, size=(300, len(FEATURE_NAMES)))
    model = fit_residual([(x, _quadratic(x))])
    again = ResidualModel.from_dict(model.to_dict())
    np.testing.assert_array_equal(again.predict(x), model.predict(x))
    far = np.full((1, len(FEATURE_NAMES)), 5.0)
    assert again.outside(far).all() and not again.outside(np.full((1, len(FEATURE_NAMES)), 0.5)).any()
    with pytest.raises(ParameterError, match="features"):
        ResidualModel.from_dict({**model.to_dict(), "features": ["depth"]})


def test_the_corrected_log_is_the_log_minus_the_residual():
    log = CycleLog.load(LOG)
    state = payload_contact_state(log, DEFAULT_PAYLOAD)
    x = features(state, log)
    assert x.shape == (len(log), len(FEATURE_NAMES)) and np.all(np.isfinite(x))
    model = fit_residual([(x, np.column_stack([x[:, 0], -x[:, 1]]))])
    r_t, r_n = residual_forces(model, state, log)
    shifted = corrected_log(model, state, log)
    np.testing.assert_allclose(shifted.tangential + r_t, log.tangential, rtol=0, atol=1e-9)
    np.testing.assert_allclose(shifted.normal + r_n, log.normal, rtol=0, atol=1e-9)
    np.testing.assert_allclose(r_t, model.predict(x)[:, 0] * force_scale(log))
