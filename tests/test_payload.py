"""The payload state: known answers, properties, the CasADi form and the fit on plant logs."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wheelloader.estimator import CycleLog
from wheelloader.estimator.errors import CalibrationError, ParameterError
from wheelloader.estimator.payload import (
    PayloadOptions,
    fit_payload,
    kept_fill,
    kept_volume,
    payload_contact_state,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "mpm"


def test_small_cuts_keep_the_retained_share_and_large_cuts_the_heaped_capacity():
    opts = PayloadOptions(retention=0.8, heap_factor=0.6, sharpness=4.0)
    assert kept_volume(1e-6, 0.2, opts) == pytest.approx(0.8e-6, rel=1e-9)
    assert kept_volume(1e3, 0.2, opts) == pytest.approx(0.12, rel=1e-6)
    assert kept_volume(0.0, 0.2, opts, initial=0.05) == pytest.approx(0.05)


@given(st.floats(0.05, 1.0), st.floats(0.1, 3.0), st.floats(1.0, 50.0),
       st.lists(st.floats(0.0, 2.0), min_size=2, max_size=20))
def test_kept_volume_is_monotone_and_bounded(r, h, p, removed):
    opts = PayloadOptions(r, h, p)
    grid = np.sort(np.asarray(removed))
    v = kept_volume(grid, 0.2, opts)
    assert np.all(np.diff(v) >= -1e-15)
    assert np.all(v <= h * 0.2 * (1 + 1e-12))
    assert np.all(v <= r * grid + 1e-15)


@pytest.mark.parametrize("bad", [dict(retention=0.0), dict(retention=1.5), dict(heap_factor=-1.0),
                                 dict(sharpness=0.5), dict(sharpness=float("nan"))])
def test_bad_options_are_refused(bad):
    with pytest.raises(ParameterError):
        PayloadOptions(**bad)


def test_casadi_form_matches_numpy():
    casadi = pytest.importorskip("casadi")
    opts = PayloadOptions(0.9, 0.6, 2.5)
    x = casadi.SX.sym("x")
    f = casadi.Function("f", [x], [kept_volume(x, 0.2, opts, initial=0.01)])
    for value in (0.0, 0.03, 0.1, 0.4):
        assert float(f(value)) == pytest.approx(float(kept_volume(value, 0.2, opts, initial=0.01)), rel=1e-12)


def test_fit_on_plant_logs_predicts_kept_fill_of_a_held_out_soil():
    train = [CycleLog.load(p) for p in sorted(DATA.glob("*.csv")) if not p.name.startswith("dirt")]
    test = [CycleLog.load(p) for p in sorted(DATA.glob("dirt_path*.csv"))]
    opts = fit_payload(train)
    for log in test:
        state = payload_contact_state(log, opts)
        predicted = kept_fill(state, log.bucket.capacity, opts)
        assert predicted == pytest.approx(float(log.fill_volume[-1]), rel=0.15)
        assert np.all(np.diff(state.fill_volume) >= -1e-15)


def test_fit_needs_a_logged_fill(tmp_path):
    log = CycleLog.load(DATA / "sand_path1.csv")
    bare = CycleLog(log.path, log.tangential, log.normal, log.pile, log.bucket)
    with pytest.raises(CalibrationError, match="fill_volume"):
        fit_payload([bare])
