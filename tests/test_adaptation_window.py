"""The loop's calibration window and its rule for untrustworthy fits (Calibrating.update)."""

from __future__ import annotations

import numpy as np
import pytest

from wheelloader.adaptation import DEFAULT_WINDOW, Calibrating
from wheelloader.estimator import WheelloaderError, preset
from wheelloader.estimator.synthetic import random_bezier_path, synthetic_cycle


def _logs(count, soil="dirt"):
    rng = np.random.default_rng(3)
    return [synthetic_cycle(soil, random_bezier_path(rng, name=f"c{k}"), noise=0.02, seed=k) for k in range(count)]


def test_window_calibrates_on_the_last_cycles():
    strategy = Calibrating(preset("sand"), window=2)
    messages = [strategy.update(log, preset("dirt")).message for log in _logs(3)]
    assert messages[0].endswith("on 1 cycle") and messages[1].endswith("on 2 cycles")
    assert messages[2].endswith("on 2 cycles") and len(strategy.recent) == 2
    assert strategy.previous.cycle_count == 2
    assert Calibrating(preset("sand")).window == DEFAULT_WINDOW
    assert Calibrating(preset("sand"), "multi-stage").window == 1


def test_untrustworthy_fit_keeps_the_previous_one_when_asked():
    good = _logs(1)[0]
    flat = synthetic_cycle("dirt", noise=0.0, force_scale=1.0)
    flat = type(flat)(flat.path, np.full(len(flat), 1.0), np.full(len(flat), 1.0), flat.pile, flat.bucket)
    strict = Calibrating(preset("sand"), keep_untrustworthy=False)
    assert strict.update(good, preset("dirt")).ok
    kept = strict.params
    step = strict.update(flat, preset("dirt"))
    assert not step.ok and "not trustworthy" in step.message and strict.params == kept
    lenient = Calibrating(preset("sand"))
    lenient.update(good, preset("dirt"))
    assert lenient.update(flat, preset("dirt")).ok and lenient.params != kept


def test_bad_windows_are_rejected():
    for bad in (0, -1, 1.5, True):
        with pytest.raises(WheelloaderError, match="window"):
            Calibrating(preset("sand"), window=bad)
    with pytest.raises(WheelloaderError, match="window must be 1"):
        Calibrating(preset("sand"), "multi-stage", window=2)
