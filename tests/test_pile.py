import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from wheelloader.estimator import ParameterError, Pile, default_path


def test_ideal_slope_geometry():
    pile = Pile.ideal_slope(math.radians(30.0), toe_x=1.0, length=3.0)
    assert pile.surface_height(0.5) == 0.0
    assert pile.surface_height(2.0) == pytest.approx(math.tan(math.radians(30.0)))
    assert pile.slope_angle(2.0) == pytest.approx(math.radians(30.0))
    assert pile.slope_angle(0.0) == pytest.approx(0.0)
    xs = np.linspace(-1, 5, 7)
    assert np.allclose(pile.surface_height(xs), [pile.surface_height(float(v)) for v in xs])


def test_trapezoid_area_is_exact():
    pile = Pile.trapezoid(angle=math.radians(45.0), height=1.0, top_length=1.0)
    # front 1 m, top 1 m, back 1 m: area = 0.5 + 1 + 0.5
    assert pile.area() == pytest.approx(2.0, rel=1e-12)


def test_slope_angle_is_continuous_across_the_crest():
    pile = Pile.trapezoid()
    crest = 1.0 / math.tan(math.radians(30.0))
    xs = np.linspace(crest - 0.3, crest + 0.3, 2001)
    alpha = pile.slope_angle(xs)
    assert np.max(np.abs(np.diff(alpha))) < 0.01


def test_carving_balances_volume_to_1e_9():
    pile = Pile.trapezoid()
    path = default_path()
    for capacity in (0.2, 0.05):  # second case spills
        result = pile.carve(path.x, path.z, width=1.0, capacity=capacity)
        removed_from_area = pile.volume(1.0) - result.pile.volume(1.0)
        assert result.removed == pytest.approx(removed_from_area, rel=1e-9)
        assert abs(result.balance_error) <= 1e-9 * result.removed
        assert result.in_bucket <= capacity * (1 + 1e-12)
    assert result.spilled > 0.0
    assert np.all(np.diff(result.fill_history) >= 0.0)


@settings(max_examples=40, deadline=None)
@given(depth=st.floats(0.0, 0.5), x_end=st.floats(0.5, 2.5), initial=st.floats(0.0, 0.1),
       capacity=st.floats(0.05, 0.5))
@example(depth=1.192092896e-07, x_end=0.5, initial=0.0, capacity=0.5)  # found by hypothesis: cancellation
def test_carving_balance_property(depth, x_end, initial, capacity):
    pile = Pile.ideal_slope(math.radians(30.0))
    xs = np.linspace(-0.2, x_end, 50)
    zs = np.maximum(0.0, pile.surface_height(xs) - depth) + 0.0 * xs
    result = pile.carve(xs, zs, 1.0, capacity, initial_fill=min(initial, capacity))
    assert abs(result.balance_error) <= 1e-9 * max(result.removed, result.in_bucket)
    # the difference of two pile volumes carries their rounding (~1e-16 of the volume per term summed): a carve
    # of 1e-7 m depth removes ~6e-8 m^3, which two ~5 m^3 volumes give only to ~1e-15 m^3
    assert result.removed == pytest.approx(pile.volume(1.0) - result.pile.volume(1.0), rel=1e-9,
                                           abs=1e-12 * pile.volume(1.0))
    assert np.all(result.pile.heights <= pile.heights)


def test_relaxation_conserves_area_and_limits_slopes():
    pile = Pile.from_polyline([0, 1, 1.2, 3], [0, 0, 0.5, 0.5], spacing=0.02)
    relaxed = pile.relaxed(math.radians(35.0))
    assert relaxed.area() == pytest.approx(pile.area(), rel=1e-12)
    slopes = np.abs(np.diff(relaxed.heights)) / relaxed.spacing
    assert np.max(slopes[1:-1]) <= math.tan(math.radians(35.0)) + 1e-6
    assert np.max(slopes) < np.max(np.abs(np.diff(pile.heights)) / pile.spacing)


def _relaxed_node_by_node(pile, repose_angle, iterations):
    """:meth:`Pile.relaxed`'s rule one pair at a time in plain Python floats (the same IEEE operations)."""
    z = [float(v) for v in pile.heights]
    limit = pile.spacing * math.tan(repose_angle)
    for _ in range(iterations):
        moved = False
        for first in (1, 2):
            for i in range(first, len(z) - 2, 2):
                diff = z[i + 1] - z[i]
                excess = abs(diff) - limit
                if excess > 1e-9:
                    moved = True
                    move = 0.5 * excess * ((diff > 0) - (diff < 0))
                    z[i + 1] -= move
                    z[i] += move
        if not moved:
            break
    return np.array(z)


@settings(max_examples=30, deadline=None)
@given(heights=st.lists(st.floats(0.0, 1.0), min_size=2, max_size=40), angle=st.floats(0.1, 1.4),
       iterations=st.integers(0, 60))
def test_relaxation_is_the_pairwise_rule_bit_for_bit(heights, angle, iterations):
    pile = Pile(0.0, 0.05, np.array(heights))
    assert np.array_equal(pile.relaxed(angle, iterations=iterations).heights,
                          _relaxed_node_by_node(pile, angle, iterations))


def test_round_trip_and_equality():
    pile = Pile.trapezoid()
    assert Pile.from_dict(pile.to_dict()) == pile
    assert Pile.from_dict({"x": [0, 1, 2], "z": [0, 0.5, 0.5]}).surface_height(0.5) == pytest.approx(0.25)


@pytest.mark.parametrize("x,z", [([0, 1], [0]), ([1, 0], [0, 1]), ([0, float("nan")], [0, 1]), ([0], [0])])
def test_bad_polylines(x, z):
    with pytest.raises(ParameterError):
        Pile.from_polyline(x, z)


def test_angles_in_degrees_are_rejected():
    with pytest.raises(ParameterError, match="radians"):
        Pile.ideal_slope(30.0)
