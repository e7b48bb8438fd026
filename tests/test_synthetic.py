"""Synthetic cycle generator: known soil, noise model, reproducibility."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wheelloader.estimator import Bucket, Pile, contact_state, default_path, preset, soil_forces
from wheelloader.estimator.errors import ParameterError
from wheelloader.estimator.synthetic import (
    band_limited_noise,
    random_bezier_path,
    random_soil,
    synthetic_cycle,
)


def test_noise_free_cycle_is_the_model():
    path, pile, bucket = default_path(), Pile.trapezoid(), Bucket()
    cycle = synthetic_cycle("dirt", path, pile, bucket, noise=0.0)
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    f = soil_forces(preset("dirt"), state, bucket)
    np.testing.assert_allclose(cycle.tangential, f.tangential)
    np.testing.assert_allclose(cycle.normal, f.normal)
    np.testing.assert_allclose(cycle.metadata["true_tangential"], f.tangential)
    assert cycle.metadata["soil"] == preset("dirt").to_dict()
    np.testing.assert_allclose(cycle.fill_volume, state.fill_volume)
    assert cycle.pile_after is not None


def test_seeded_noise_is_reproducible_and_scaled():
    a = synthetic_cycle("gravel", noise=0.05, seed=7)
    b = synthetic_cycle("gravel", noise=0.05, seed=7)
    c = synthetic_cycle("gravel", noise=0.05, seed=8)
    np.testing.assert_array_equal(a.tangential, b.tangential)
    assert not np.array_equal(a.tangential, c.tangential)
    err = a.tangential - np.asarray(a.metadata["true_tangential"])
    scale = a.metadata["force_scale"]
    assert scale == pytest.approx(np.max(np.hypot(a.metadata["true_tangential"], a.metadata["true_normal"])))
    assert np.std(err) == pytest.approx(0.05 * scale, rel=0.2)


def test_bias_is_a_constant_offset():
    cyc = synthetic_cycle("sand", noise=0.0, bias=(0.1, -0.05), seed=1)
    scale = cyc.metadata["force_scale"]
    np.testing.assert_allclose(cyc.tangential - cyc.metadata["true_tangential"], 0.1 * scale)
    np.testing.assert_allclose(cyc.normal - cyc.metadata["true_normal"], -0.05 * scale)


def test_vibration_power_lies_in_its_band():
    rng = np.random.default_rng(0)
    sig = band_limited_noise(rng, 4096, 60.0, (5.0, 15.0))
    assert np.std(sig) == pytest.approx(1.0)
    spec = np.abs(np.fft.rfft(sig)) ** 2
    freq = np.fft.rfftfreq(4096, 1 / 60.0)
    inside = spec[(freq >= 5.0) & (freq <= 15.0)].sum()
    assert inside / spec.sum() > 0.999
    cyc = synthetic_cycle("dirt", noise=0.0, vibration=0.03, seed=2)
    resid = cyc.normal - np.asarray(cyc.metadata["true_normal"])
    assert np.std(resid) == pytest.approx(0.03 * cyc.metadata["force_scale"], rel=1e-6)


@pytest.mark.parametrize("kwargs", [{"noise": -0.1}, {"vibration": float("nan")}, {"bias": (1, 2, 3)},
                                    {"vibration": 0.1, "vibration_band": (20.0, 10.0)}, {"force_scale": 0.0}])
def test_bad_arguments_raise(kwargs):
    with pytest.raises(ParameterError):
        synthetic_cycle("dirt", **kwargs)


def test_random_problems_are_valid():
    rng = np.random.default_rng(3)
    for _ in range(20):
        soil = random_soil(rng)
        assert soil.out_of_bounds() == []
        path = random_bezier_path(rng)
        cyc = synthetic_cycle(soil, path, noise=0.0)
        assert np.count_nonzero(cyc.contact_state().depth > 0) > 50


def test_perturbed_preset_is_seeded_near_the_preset_and_inside_the_bounds():
    from wheelloader.estimator import PAPER_BOUNDS, preset
    from wheelloader.estimator.synthetic import perturbed_preset

    a, b = perturbed_preset("gravel", 0), perturbed_preset("gravel", 0)
    assert a == b and a != perturbed_preset("gravel", 1)
    base = preset("gravel")
    for key in ("gamma", "phi", "delta", "k_c"):
        lo, hi = PAPER_BOUNDS[key]
        assert lo <= getattr(a, key) <= hi
        assert abs(math.log(getattr(a, key) / getattr(base, key))) < 0.5
    assert a.n == base.n  # parameters outside the perturbed set stay the preset's
