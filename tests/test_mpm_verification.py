"""Closed forms of the MPM verification, and (slow) the solver against them."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from wheelloader.references.mpm import ContinuumSoil
from wheelloader.references.mpm.verification import (
    at_rest_force,
    column_runout_scaling,
    column_runout_true_2d,
    mckyes_blade,
    mckyes_blade_with_heap,
    rankine_passive,
)

SOIL_A = ContinuumSoil(1600.0, math.radians(30.0), wall_friction_angle=math.radians(20.0))
SOIL_B = ContinuumSoil(1600.0, math.radians(30.0), cohesion=1000.0, wall_friction_angle=math.radians(20.0),
                       adhesion=500.0)


def _need_taichi() -> None:
    try:
        import taichi  # noqa: F401
    except ImportError:
        if os.environ.get("WHEELLOADER_REQUIRE_MPM") == "1":
            pytest.fail("WHEELLOADER_REQUIRE_MPM=1 but taichi is not installed")
        pytest.skip('taichi not installed: pip install "wheelloader[mpm]"')


@pytest.mark.parametrize("depth, horizontal", [(0.10, 450.0), (0.15, 1013.0), (0.20, 1801.0), (0.25, 2814.0)])
def test_mckyes_vertical_blade_values(depth, horizontal):
    # the passive-wedge figures of the prototype trial (phi 30, delta 20 deg, 1600 kg/m^3)
    ref = mckyes_blade(depth, SOIL_A)
    assert ref["horizontal"] == pytest.approx(horizontal, rel=2e-3)
    assert ref["vertical"] / ref["horizontal"] == pytest.approx(-math.tan(SOIL_A.wall_friction_angle))


def test_mckyes_cohesion_and_adhesion_add_force():
    base = mckyes_blade(0.15, SOIL_A)["horizontal"]
    assert mckyes_blade(0.15, SOIL_B)["horizontal"] > base
    with pytest.raises(ValueError, match="depth"):
        mckyes_blade(0.0, SOIL_A)


def test_heap_surcharge_known_answers():
    # no heap: the flat-surface wedge
    flat = mckyes_blade(0.15, SOIL_A)
    none = mckyes_blade_with_heap(0.15, SOIL_A, lambda length: 0.0)
    assert none["horizontal"] == pytest.approx(flat["horizontal"])
    assert none["surcharge"] == 0.0
    # a heap spread evenly (mass proportional to the length it covers) is a uniform surcharge q
    q = 400.0
    even = mckyes_blade_with_heap(0.15, SOIL_A, lambda length: q * length / 9.81)
    assert even["surcharge"] == pytest.approx(q)
    assert even["horizontal"] == pytest.approx(mckyes_blade(0.15, SOIL_A, surcharge=q)["horizontal"])
    # the fixed point is consistent: q is the heap on the wedge of the returned beta
    assert even["wedge_length"] == pytest.approx(0.15 / math.tan(even["beta"]), rel=1e-6)
    # by hand: q d N_q adds to the wedge weight term, N_q = cot(beta) / den for a vertical blade
    beta, phi, delta = even["beta"], SOIL_A.friction_angle, SOIL_A.wall_friction_angle
    den = math.cos(math.pi / 2 + delta) + math.sin(math.pi / 2 + delta) / math.tan(beta + phi)
    n_gamma = (1.0 / math.tan(beta)) / (2.0 * den)
    total = 1600 * 9.81 * 0.15**2 * n_gamma + q * 0.15 * (1.0 / math.tan(beta)) / den
    assert even["total"] == pytest.approx(total, rel=1e-9)


def test_true_2d_column_fit():
    assert column_runout_true_2d(0.5) is None
    assert column_runout_true_2d(1.0) == pytest.approx(3.25)
    assert column_runout_true_2d(3.0) == pytest.approx(3.80 * 3.0**0.73)
    # true-2-D columns run out further than quasi-2-D channels at every aspect ratio where both are given
    for a in (0.8, 1.0, 2.0, 3.0):
        assert column_runout_true_2d(a) > column_runout_scaling(a)["lube"]
    with pytest.raises(ValueError):
        column_runout_true_2d(-1.0)


def test_rankine_and_at_rest():
    kp = (1 + 0.5) / (1 - 0.5)
    assert rankine_passive(0.3, SOIL_A) == pytest.approx(0.5 * kp * 1600 * 9.81 * 0.09)
    assert at_rest_force(0.3, SOIL_A) == pytest.approx(0.5 * 0.5 * 1600 * 9.81 * 0.09)
    assert rankine_passive(0.3, SOIL_B) > rankine_passive(0.3, SOIL_A)


def test_column_scaling_regimes():
    assert column_runout_scaling(1.0)["lube"] == pytest.approx(1.2)
    assert column_runout_scaling(4.0)["lube"] == pytest.approx(1.9 * 4.0 ** (2 / 3))
    mid = column_runout_scaling(2.3)["lube"]
    assert min(1.2 * 2.3, 1.9 * 2.3 ** (2 / 3)) <= mid <= max(1.2 * 2.3, 1.9 * 2.3 ** (2 / 3))
    with pytest.raises(ValueError):
        column_runout_scaling(0.0)


@pytest.mark.slow
@pytest.mark.parametrize("soil", [SOIL_A, SOIL_B], ids=["frictional", "cohesive"])
def test_blade_matches_mckyes(soil):
    _need_taichi()
    from wheelloader.references.mpm.verification import run_blade

    depth = 0.15
    res = run_blade(depth, soil, depth / 10)
    travel = res.extra["travel"]
    window = (travel >= 0.5 * depth) & (travel <= depth)
    horizontal = -np.mean(res.force[window, 0])
    # soil heaps up ahead of the blade and loads the wedge: McKyes with that heap as its surcharge q
    heap = np.mean(res.extra["heap_mass"][window], axis=0)
    cumulative = np.concatenate([[0.0], np.cumsum(heap)])
    edges = res.extra["heap_bin_edges"]
    heaped = mckyes_blade_with_heap(depth, soil, lambda length: float(np.interp(length, edges, cumulative)))
    assert heaped["surcharge"] > 0.0
    assert horizontal == pytest.approx(heaped["horizontal"], rel=0.10)
    # the force rises with the heap: above the flat-surface wedge over this window
    assert horizontal > mckyes_blade(depth, soil)["horizontal"]
    # the soil slides up the blade: the vertical force is friction plus adhesion, lifting the blade
    vertical = np.mean(res.force[window, 1])
    assert vertical > 0.0


@pytest.mark.slow
def test_smooth_wall_at_rest_and_passive():
    _need_taichi()
    from wheelloader.references.mpm.verification import run_wall

    res = run_wall(0.3, SOIL_A, 0.015, push=0.06)
    rest = -np.mean(res.force[(res.times > 0.45) & (res.times < 0.6), 0])
    passive = -np.mean(res.force[res.extra["displacement"] >= 0.04, 0])
    assert rest == pytest.approx(at_rest_force(0.3, SOIL_A), rel=0.15)
    assert passive == pytest.approx(rankine_passive(0.3, SOIL_A), rel=0.15)
