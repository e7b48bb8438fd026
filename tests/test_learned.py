"""force_model="fee-learned": the shipped artifact, the NumPy and CasADi networks, range flags, calibrate/predict."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wheelloader.estimator import CycleLog, calibrate, predict
from wheelloader.estimator.calibration import CalibrationOptions
from wheelloader.estimator.errors import ParameterError
from wheelloader.estimator.learned import (
    DEFAULT_ARTIFACT,
    INPUT_NAMES,
    LearnedModel,
    casadi_correction,
    contact_gate,
    default_learned_model,
)
from wheelloader.estimator.learned_plant import learned_correction
from wheelloader.estimator.machine import Bucket
from wheelloader.estimator.soil import preset

LOG = Path(__file__).resolve().parents[1] / "data" / "mpm" / "sand_path2.csv"


@pytest.fixture(scope="module")
def model():
    return default_learned_model()


def test_artifact_is_small_versioned_and_states_its_split(model):
    assert DEFAULT_ARTIFACT.stat().st_size < 1_000_000
    assert model.version != "unversioned"
    manifest = model.manifest
    assert manifest["command"].startswith("python benchmarks/fee_learned.py")
    train = [f for files in manifest["split"]["train"].values() for f in files]
    test = [f for files in manifest["split"]["test"].values() for f in files]
    assert train and test and not set(train) & set(test)
    # the held-out soils and pile never reach training
    assert not [f for f in train if "dirt" in f or "modified_sand" in f or "slope25" in f]


def test_round_trip_and_bad_artifacts(model, tmp_path):
    again = LearnedModel.from_dict(json.loads(json.dumps(model.to_dict())))
    x = np.tile(model.mean, (3, 1))
    np.testing.assert_array_equal(again.correction(x), model.correction(x))
    bad = model.to_dict() | {"format": "other"}
    with pytest.raises(ParameterError, match="format"):
        LearnedModel.from_dict(bad)
    with pytest.raises(ParameterError, match="inputs"):
        LearnedModel.from_dict(model.to_dict() | {"inputs": ["depth"]})
    with pytest.raises(ParameterError, match="w2"):
        LearnedModel.from_dict(model.to_dict() | {"w2": [[1.0, 2.0]]})


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=len(INPUT_NAMES), max_size=len(INPUT_NAMES)))
def test_casadi_twin_agrees_with_numpy(u):
    import casadi as ca

    model = default_learned_model()
    # inputs spread over and beyond the trusted range (both sides of the clip)
    x = model.low + (np.asarray(u) + 1.0) / 2.0 * (model.high - model.low)
    sym = ca.SX.sym("x", 1, len(INPUT_NAMES))
    fn = ca.Function("r", [sym], [casadi_correction(model, sym)])
    np.testing.assert_allclose(np.asarray(fn(x[None, :])), model.correction(x[None, :]), rtol=1e-12, atol=1e-12)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0), min_size=len(INPUT_NAMES), max_size=len(INPUT_NAMES)),
       st.floats(-5.0, 0.0))
def test_the_correction_is_exactly_zero_out_of_the_soil(u, ramp):
    """At and above the surface (contact ramp <= 0) the correction is 0 whatever the other inputs."""
    model = default_learned_model()
    x = model.low + (np.asarray(u) + 1.0) / 2.0 * (model.high - model.low)
    x[1] = ramp
    assert np.all(model.correction(x[None, :]) == 0.0)
    x[1] = 1.0 + abs(ramp)  # from CONTACT_DEPTH deep the gate is 1: the network alone
    np.testing.assert_array_equal(model.correction(x[None, :]), model.ungated(x[None, :]))


def test_the_gate_is_a_c1_smoothstep():
    t = np.array([-1.0, 0.0, 0.25, 0.5, 1.0, 2.0])
    np.testing.assert_allclose(contact_gate(t), [0.0, 0.0, 0.15625, 0.5, 1.0, 1.0])
    h = 1e-6  # one-sided slopes at both ends of the ramp are 0 (continuous derivative)
    assert contact_gate(np.array([h]))[0] / h < 1e-5
    assert (1.0 - contact_gate(np.array([1.0 - h]))[0]) / h < 1e-5


def test_the_env_correction_is_zero_out_of_the_soil_and_equals_its_rows(model):
    corr = learned_correction(preset("gravel"), Bucket(), model)
    assert corr.single(0.0, 0.3, 0.5, 0.1, 0.0, 0.0, 0.5) == (0.0, 0.0)
    assert corr.single(-0.1, 0.3, 0.5, 0.1, 0.05, 0.05, 0.5) == (0.0, 0.0)
    depth = np.array([-0.1, 0.0, 0.005, 0.01, 0.05, 0.2])
    rows = corr.rows(depth, *(np.full(depth.size, v) for v in (0.3, 0.5, 0.1, 0.05, 0.04, 0.5)))
    single = np.array([corr.single(d, 0.3, 0.5, 0.1, 0.05, 0.04, 0.5) for d in depth])
    np.testing.assert_allclose(np.column_stack(rows), single, rtol=1e-12, atol=1e-9)
    assert np.all(single[:2] == 0.0) and np.all(single[2:] != 0.0)


def test_inputs_outside_the_training_range_are_flagged_and_clipped(model):
    inside = np.tile((model.low + model.high) / 2.0, (2, 1))
    beyond = inside.copy()
    beyond[1, 0] = model.high[0] + 1.0  # far deeper than anything trained on
    edge = inside.copy()
    edge[1, 0] = model.high[0]
    assert list(model.outside(inside)) == [False, False]
    assert list(model.outside(beyond)) == [False, True]
    np.testing.assert_array_equal(model.correction(beyond), model.correction(edge))


@pytest.fixture(scope="module")
def log():
    return CycleLog.load(LOG)


@pytest.fixture(scope="module")
def learned_cal(log):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate(log, options=CalibrationOptions(force_model="fee-learned", grid=(4, 4, 3), n_starts=1))


def test_calibration_carries_the_learned_model_and_predict_reproduces_it(log, learned_cal, model):
    assert learned_cal.force_model == "fee-learned"
    assert learned_cal.payload == model.payload
    assert learned_cal.settings["learned"]["version"] == model.version
    pred = predict(learned_cal, log)
    assert pred.outside_training is not None and pred.outside_training.shape == (len(log),)
    np.testing.assert_allclose(pred.tangential, learned_cal.predicted_tangential, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(pred.normal, learned_cal.predicted_normal, rtol=1e-9, atol=1e-6)
    # the correction is what sets it apart from its base at the same soil
    plain = predict(learned_cal.params, log, force_model="fee-payload-depth", payload=model.payload)
    assert not np.allclose(plain.tangential, pred.tangential)


def test_the_soil_is_one_refit_of_the_base_s_own_fit(log, learned_cal, model):
    """CALIBRATION_PASSES (1): the base's fit of one cycle (LEARNED_BASE, the soil the network was trained at),
    then the base refitted once to the forces less the correction at that soil."""
    from wheelloader.estimator.force_models import LEARNED_BASE
    from wheelloader.estimator.learned import CALIBRATION_PASSES, corrected_log

    assert LEARNED_BASE == model.manifest["base"]
    opts = CalibrationOptions(force_model=LEARNED_BASE, payload=model.payload, grid=(4, 4, 3), n_starts=1)
    soil = calibrate(log, options=opts).params
    for _ in range(CALIBRATION_PASSES):
        soil = calibrate(corrected_log(model, log, soil, model.payload)[0], options=opts).params
    assert learned_cal.params.to_dict() == soil.to_dict()


def test_other_models_have_no_range_flags(log, learned_cal):
    assert predict(learned_cal.params, log).outside_training is None
