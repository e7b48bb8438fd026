"""The step bookkeeping of wheelloader.envs.bookkeeping gives the same numbers on every backend: Python floats
(the single env), NumPy arrays (the batched env, verify_plan) and CasADi expressions (the planner's NLP)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from wheelloader.envs.bookkeeping import (
    cycle_done,
    cycle_progress,
    exact_pos,
    outside_validity,
    reward_terms,
    step_work,
)
from wheelloader.envs.config import RewardWeights
from wheelloader.estimator import FLAG_OUT_OF_SOIL
from wheelloader.planner.verify import cycle_end_index

RNG = np.random.default_rng(0)
N = 200
F_T, F_N = RNG.uniform(-2e3, 3e4, N), RNG.uniform(-2e3, 3e4, N)
DX, DZ = RNG.uniform(-0.02, 0.02, N), RNG.uniform(-0.02, 0.02, N)
THETA, LOAD = RNG.uniform(-0.8, 1.3, N), RNG.uniform(0.0, 5e3, N)


def test_exact_pos_is_max_with_zero():
    v = np.concatenate([RNG.normal(0.0, 1e3, 1000), [0.0, -0.0, 1e-310, -1e-310, 1e300, -1e300]])
    np.testing.assert_array_equal(exact_pos(v), np.maximum(v, 0.0))
    assert all(exact_pos(float(x)) == max(float(x), 0.0) for x in v)


def test_step_work_floats_arrays_and_casadi_agree():
    soil, payload = step_work(F_T, F_N, DX, DZ, THETA, LOAD)
    assert np.all(soil >= 0.0) and np.all(payload >= 0.0) and np.any(soil > 0.0) and np.any(payload > 0.0)
    for i in range(N):
        s, p = step_work(float(F_T[i]), float(F_N[i]), float(DX[i]), float(DZ[i]), float(THETA[i]),
                         float(LOAD[i]), cos=math.cos, sin=math.sin)
        assert (s, p) == (soil[i], payload[i])  # bit for bit: the single env equals the batched env
    sym = [ca.SX.sym(n) for n in ("ft", "fn", "dx", "dz", "th", "w")]
    exact = ca.Function("work", sym, list(step_work(*sym, cos=ca.cos, sin=ca.sin, pos=lambda v: ca.fmax(v, 0.0))))
    s_ca, p_ca = exact(F_T, F_N, DX, DZ, THETA, LOAD)
    np.testing.assert_allclose(np.array(s_ca).ravel(), soil, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(np.array(p_ca).ravel(), payload, rtol=1e-12, atol=1e-9)


def test_work_is_force_along_the_displacement():
    """Pushing straight along the blade: the work is F_T times the distance; lifting: W_load times dz."""
    soil, payload = step_work(1000.0, 0.0, 0.1, 0.0, 0.0, 500.0, cos=math.cos, sin=math.sin)
    assert soil == pytest.approx(100.0) and payload == 0.0
    soil, payload = step_work(0.0, 2000.0, 0.0, 0.05, 0.0, 500.0, cos=math.cos, sin=math.sin)
    assert soil == pytest.approx(100.0) and payload == pytest.approx(25.0)
    assert step_work(1000.0, 0.0, -0.1, -0.1, 0.0, 500.0, cos=math.cos, sin=math.sin) == (0.0, 0.0)


def test_reward_terms_and_validity_floats_equal_arrays():
    weights = RewardWeights(validity=0.5, force=2.0)
    depth = RNG.uniform(-0.1, 0.3, N)
    flags = RNG.choice([0, FLAG_OUT_OF_SOIL, 2, 4 | FLAG_OUT_OF_SOIL], N)
    stalled = RNG.random(N) < 0.3
    gain, energy = RNG.uniform(0, 1e-3, N), RNG.uniform(0, 300.0, N)
    invalid = outside_validity(depth, flags)
    assert invalid.dtype == bool and np.array_equal(invalid, (depth > 0) & ((flags & ~FLAG_OUT_OF_SOIL) != 0))
    arrays = reward_terms(weights, 1.2, 2e4, 2.5e4, gain, energy, invalid, stalled, F_T, F_N)
    for i in range(N):
        inv = outside_validity(float(depth[i]), int(flags[i]))
        assert isinstance(inv, bool) and inv == invalid[i]
        scalars = reward_terms(weights, 1.2, 2e4, 2.5e4, float(gain[i]), float(energy[i]), inv, bool(stalled[i]),
                               float(F_T[i]), float(F_N[i]))
        assert scalars == tuple(a[i] for a in arrays)
    assert set(np.unique(arrays[2])) <= {0.0, -0.5} and set(np.unique(arrays[3])) <= {0.0, -1.0}
    assert not np.any(np.signbit(arrays[2][~invalid]))  # no -0.0 terms


def test_cycle_rule_step_by_step_equals_the_path_version():
    """The env applies the rule sample by sample; verify_plan's cycle_end_index along a whole path."""
    for seed in range(30):
        rng = np.random.default_rng(seed)
        n = 60
        in_soil = np.zeros(n, bool)
        start = rng.integers(1, 20)
        in_soil[start:start + rng.integers(1, 30)] = True
        in_soil[rng.integers(0, n, 3)] ^= True
        fill = np.cumsum(in_soil * rng.uniform(0, 0.02, n))
        z = rng.uniform(0.0, 1.5, n)
        clearance = np.where(in_soil, -0.05, rng.uniform(-0.03, 0.2, n))
        crest, exit_clearance, min_fill = 1.0, 0.02, rng.choice([0.0, 0.05])
        touched = entered = False
        first = None
        for k in range(n):
            touched, entered = cycle_progress(touched, entered, bool(in_soil[k]), float(fill[k]), min_fill)
            if first is None and cycle_done(touched, entered, float(z[k]), float(clearance[k]), crest,
                                            exit_clearance):
                first = k
        assert cycle_end_index(in_soil, clearance, fill, exit_clearance, min_fill, z=z, crest=crest) == first
