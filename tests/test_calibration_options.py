"""CalibrationOptions (#30 item 3): validated settings, the deprecated keywords, one outcome per method."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import pickle
import textwrap

import pytest

from wheelloader.estimator import CalibrationError, ModelOptions, ParameterError, preset, synthetic_cycle
from wheelloader.estimator.calibration import CalibrationOptions, api, calibrate


def _untimed(cal):
    """The calibration with its wall times zeroed (everything else must match bit for bit)."""
    return dataclasses.replace(cal, time_s=0.0, stages=[dataclasses.replace(s, time_s=0.0) for s in cal.stages])


def _same(a, b) -> bool:
    return pickle.dumps(_untimed(a), protocol=4) == pickle.dumps(_untimed(b), protocol=4)


@pytest.fixture(scope="module")
def cycle():
    return synthetic_cycle("dirt", noise=0.03, seed=5)


def test_options_are_frozen_and_canonical():
    opts = CalibrationOptions(method=" Multi ", grid=[5, 5, 4], initial="gravel", bounds={"n": (0.5, 1.0)})
    assert opts.method == "multi-stage" and opts.grid == (5, 5, 4)
    assert opts.initial == preset("gravel") and opts.bounds["n"] == (0.5, 1.0) and len(opts.bounds) == 8
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.lam = 0.3
    assert CalibrationOptions().method == "varpro" and CalibrationOptions(method="default").method == "varpro"


@pytest.mark.parametrize(("settings", "match"), [
    ({"method": "newton"}, "unknown calibration method"),
    ({"lam": 1.5}, "lam"),
    ({"lam": float("nan")}, "lam"),
    ({"sigma": -1.0}, "sigma"),
    ({"max_iter": 0}, "max_iter"),
    ({"max_iter": 2.5}, "max_iter"),
    ({"grid": (9, 9)}, "grid"),
    ({"grid": (9, 0, 8)}, "grid"),
    ({"n_starts": True}, "n_starts"),
    ({"min_samples": 0}, "min_samples"),
    ({"regularize": 1}, "regularize"),
    ({"forgetting": 0.0}, "forgetting"),
    ({"forgetting": 0.5, "cycle_weights": [1.0, 1.0]}, "not both"),
    ({"cycle_weights": [1.0, -1.0]}, "cycle_weights"),
    ({"fill": "bucket"}, "fill"),
    ({"band_noise": "loo"}, "band_noise"),
    ({"prior": "peat"}, "soil class"),
    ({"prior": "granular", "method": "multi-stage"}, "varpro"),
    ({"model_options": ModelOptions(carried_load=True), "method": "single"}, "varpro"),
    ({"model_options": "paper"}, "model_options"),
    ({"bounds": {"phi": (0.5, 0.2)}}, "phi"),
    ({"initial": "no-such-soil"}, "initial"),
])
def test_bad_settings_fail_when_made(settings, match):
    with pytest.raises(CalibrationError, match=match):
        CalibrationOptions(**settings)


def test_slope_window_keeps_its_error_class():
    with pytest.raises(ParameterError, match="slope_window"):
        CalibrationOptions(slope_window=0.0)


def test_deprecated_keywords_warn_and_give_the_same_calibration(cycle):
    new = calibrate(cycle, options=CalibrationOptions(method="varpro", grid=(5, 5, 4), n_starts=2, lam=0.4,
                                                      model_options=ModelOptions(carried_load=True)))
    with pytest.warns(DeprecationWarning, match="CalibrationOptions"):
        old = calibrate(cycle, "varpro", grid=(5, 5, 4), n_starts=2, lam=0.4,
                        options=ModelOptions(carried_load=True))
    assert _same(new, old)
    with pytest.warns(DeprecationWarning):
        old_kw = calibrate(cycle=cycle, method="single", max_iter=3)
    assert _same(old_kw, calibrate(cycle, options=CalibrationOptions(method="single-stage", max_iter=3)))


def test_options_positional_and_mixed_calls(cycle):
    opts = CalibrationOptions(grid=(3, 3, 3), n_starts=1)
    assert _same(calibrate(cycle, opts), calibrate(cycle, options=opts))
    with pytest.raises(TypeError, match="not both"):
        calibrate(cycle, options=opts, lam=0.3)
    with pytest.raises(TypeError, match="unexpected"):
        calibrate(cycle, lamda=0.3)
    with pytest.raises(TypeError, match="multiple values"):
        calibrate(cycle, "varpro", method="varpro")


def test_one_cycle_and_a_list_of_one_take_the_same_path(cycle):
    opts = CalibrationOptions(grid=(3, 3, 3), n_starts=1)
    assert _same(calibrate(cycle, options=opts), calibrate([cycle], options=opts))


def test_each_method_fit_returns_a_method_fit(cycle):
    assert set(api.FIT_FUNCTIONS) == {"varpro", "single-stage", "multi-stage"}
    cal = calibrate(cycle, options=CalibrationOptions(method="multi", max_iter=5))
    assert cal.method == "multi-stage" and [s.name for s in cal.stages][:1] == ["stage 1"]
    assert cal.settings["maxiter"] == 5 and cal.settings["sigma"] == 3.0


def _lengths(module) -> dict[str, int]:
    tree = ast.parse(textwrap.dedent(inspect.getsource(module)))
    return {n.name: n.end_lineno - n.lineno + 1 for n in tree.body if isinstance(n, ast.FunctionDef)}


def test_calibrate_is_short():
    from wheelloader.estimator.calibration import options, paper_methods

    assert _lengths(api)["calibrate"] <= 80
    for module in (api, options, paper_methods):
        long = {k: v for k, v in _lengths(module).items() if not k.startswith("_") and v > 100}
        assert not long, (module.__name__, long)
