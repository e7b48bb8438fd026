"""The estimator's scalar fast paths (what the single env steps through) equal their reference forms bit for bit.

The references below are the forms these functions had before they were made faster (NumPy-array indexing, the
generic Newton loop): the fast forms must give exactly the same floats, so that the env, the batched env and
every result built on them do not move.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wheelloader.estimator import DEFAULT_OPTIONS, Pile, SurfaceCarver, contact_single
from wheelloader.estimator.failure_angle import (
    cold_start,
    halley_step,
    log_ngamma_derivatives,
    log_ngamma_slope,
    optimal_beta_scalar,
)
from wheelloader.estimator.failure_angle_weight import _root_in_bracket
from wheelloader.estimator.kinematics import surface_contact
from wheelloader.estimator.pile import node_height, node_heights
from wheelloader.estimator.validity import clamp_angles

PILE = Pile.trapezoid()
finite = st.floats(min_value=-3.0, max_value=8.0, allow_nan=False)


def _height_reference(pile: Pile, x: float) -> float:
    """Pile.height_at as it was: NumPy scalars from the heights array."""
    u = (x - pile.x0) / pile.spacing
    z = pile.heights
    if u <= 0.0:
        return float(z[0])
    last = z.size - 1
    if u >= last:
        return float(z[last])
    i = int(u)
    return float(z[i] + (u - i) * (z[i + 1] - z[i]))


def _beta_reference(alpha, rho, phi, delta, options=DEFAULT_OPTIONS, guess=None):
    """optimal_beta_scalar's reference form: bracket checks, the cold start and the loop of halley_step on
    log_ngamma_derivatives."""
    s = rho + delta + phi
    lo = options.eps1
    hi = min(math.pi - s - options.eps2, 0.5 * math.pi - alpha)
    g, _ = log_ngamma_slope(lo, alpha, phi, s, math.tan)
    if g >= 0.0:
        return lo
    g, _ = log_ngamma_slope(hi, alpha, phi, s, math.tan)
    if g <= 0.0:
        return hi
    if guess is not None and lo < guess < hi:
        x = guess
    else:
        x = cold_start(-math.tan(alpha + hi) + 1.0 / math.tan(alpha + hi + phi), 1.0 / math.tan(s), math.sqrt,
                       math.atan2)
        x = x if lo < x < hi else 0.5 * (lo + hi)
    a, b = lo, hi
    for _ in range(60):
        g, dg, half = log_ngamma_derivatives(x, alpha, phi, s, math.tan)
        if g > 0.0:
            b = x
        else:
            a = x
        xn = halley_step(x, g, dg, half, a, b)
        if abs(xn - x) < 1e-11:
            return xn
        x = xn
    return x


def _beta_newton_from_the_middle(alpha, rho, phi, delta, options=DEFAULT_OPTIONS, guess=None):
    """The solver before the cold start and Halley's steps: Newton from the guess or the branch's middle."""
    s = rho + delta + phi
    lo = options.eps1
    hi = min(math.pi - s - options.eps2, 0.5 * math.pi - alpha)
    if log_ngamma_slope(lo, alpha, phi, s, math.tan)[0] >= 0.0:
        return lo
    if log_ngamma_slope(hi, alpha, phi, s, math.tan)[0] <= 0.0:
        return hi
    x = guess if guess is not None and lo < guess < hi else 0.5 * (lo + hi)
    return _root_in_bracket(lambda b: log_ngamma_slope(b, alpha, phi, s, math.tan), lo, hi, x, 1e-11)


@settings(max_examples=300, deadline=None)
@given(x=finite, offsets=st.lists(st.floats(-0.6, 0.6, allow_nan=False), min_size=1, max_size=6),
       base=st.floats(-1.0, 2.0, allow_nan=False))
def test_surface_heights_equal_the_array_form(x, offsets, base):
    assert PILE.height_at(x) == _height_reference(PILE, x)
    assert node_height(PILE.nodes, PILE.x0, PILE.spacing, x) == _height_reference(PILE, x)
    got = node_heights(PILE.nodes, PILE.x0, PILE.spacing, x, offsets, base)
    assert got == [_height_reference(PILE, x + dx) - base for dx in offsets]
    assert PILE.slope_angle(x, 0.1) == math.atan((_height_reference(PILE, x + 0.1) - _height_reference(PILE, x - 0.1))
                                                 / 0.2)


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-0.4, 6.0), z=st.floats(-0.1, 1.2), angle=st.floats(-0.8, 1.3))
def test_contact_equals_its_reference_form(x, z, angle):
    alpha = math.atan((_height_reference(PILE, x + 0.1) - _height_reference(PILE, x - 0.1)) / 0.2)
    height = _height_reference(PILE, x)
    vertical = height - z
    if vertical <= 0.0:
        want = (0.0, alpha - angle, alpha, 0.0)
    else:
        depth = vertical * math.cos(alpha)
        rho = alpha - angle
        want = (depth, rho, alpha, min(depth / max(abs(math.sin(rho)), math.sin(math.radians(10.0))), 0.5))
    assert contact_single(PILE, x, z, angle, 0.5, 0.1) == want
    assert surface_contact(PILE, x, z, angle, 0.5, 0.1) == (*want, height)


def _carve_reference(heights: np.ndarray, x0, sp, width, capacity, fill, segments):
    """SurfaceCarver.cut_segment as it was, on a NumPy array with a weights array."""
    weights = np.full(heights.size, sp)
    weights[0] = weights[-1] = 0.5 * sp
    removed_total, spilled = 0.0, 0.0
    for xa, za, xb, zb in segments:
        lo, hi = (xa, xb) if xa <= xb else (xb, xa)
        i0 = max(0, int(math.ceil((lo - x0) / sp - 1e-12)))
        i1 = min(heights.size - 1, int(math.floor((hi - x0) / sp + 1e-12)))
        removed_area = 0.0
        dx = xb - xa
        for i in range(i0, i1 + 1):
            xi = x0 + i * sp
            zc = min(za, zb) if dx == 0.0 else za + (zb - za) * (xi - xa) / dx
            old = heights[i]
            if zc < old:
                heights[i] = zc
                removed_area += weights[i] * (old - zc)
        removed = removed_area * width
        if removed > 0.0:
            removed_total += removed
            room = max(0.0, capacity - fill)
            taken = removed if removed <= room else room
            fill += taken
            spilled += removed - taken
    return heights, fill, spilled, removed_total


@settings(max_examples=150, deadline=None)
@given(start=st.tuples(st.floats(-0.2, 3.0), st.floats(0.0, 0.8)),
       moves=st.lists(st.tuples(st.floats(-0.05, 0.05), st.floats(-0.05, 0.05)), min_size=1, max_size=30))
def test_carving_on_a_list_equals_the_array_form(start, moves):
    carver = SurfaceCarver(PILE, 1.5, 0.6, 0.0)
    x, z = start
    segments = []
    for dx, dz in moves:
        segments.append((x, z, x + dx, z + dz))
        x, z = x + dx, z + dz
    for seg in segments:
        changes: list = []
        before = carver.state()
        carver.cut_segment(*seg, changes)
        if len(segments) % 3 == 0 and seg is segments[-1]:  # undo the last cut: back to the state before it
            carver.restore(changes, before)
            segments = segments[:-1]
    heights, fill, spilled, removed = _carve_reference(PILE.heights.copy(), PILE.x0, PILE.spacing, 1.5, 0.6, 0.0,
                                                       segments)
    assert carver.nodes == heights.tolist()
    assert (carver.fill, carver.spilled, carver.removed) == (fill, spilled, removed)
    np.testing.assert_array_equal(carver.heights, heights)


@settings(max_examples=400, deadline=None)
@given(alpha=st.floats(-0.6, 0.9), rho=st.floats(0.05, 1.6), phi=st.floats(0.2, 0.8), delta=st.floats(0.1, 0.6),
       guess=st.one_of(st.none(), st.floats(0.0, 1.6)))
def test_failure_angle_scalar_loop_equals_its_reference_form(alpha, rho, phi, delta, guess):
    assert optimal_beta_scalar(alpha, rho, phi, delta, DEFAULT_OPTIONS, guess) == _beta_reference(
        alpha, rho, phi, delta, DEFAULT_OPTIONS, guess)


@settings(max_examples=400, deadline=None)
@given(alpha=st.floats(-0.6, 0.9), rho=st.floats(0.05, 1.6), phi=st.floats(0.2, 0.8), delta=st.floats(0.1, 0.6),
       guess=st.one_of(st.none(), st.floats(0.0, 1.6)))
def test_failure_angle_moved_only_at_rounding_level(alpha, rho, phi, delta, guess):
    # the cold start and Halley's steps find the root the Newton iteration from the middle found, to rounding: the
    # old solver's own results from different starts spread by up to 2.8e-12 rad (measured on 4e5 samples). On
    # clamped angles (the solvers' domain; unclamped, a root can sit on a pole, located only to the step tolerance)
    alpha, rho = (float(v) for v in clamp_angles(alpha, rho, phi, delta)[:2])
    assert optimal_beta_scalar(alpha, rho, phi, delta, DEFAULT_OPTIONS, guess) == pytest.approx(
        _beta_newton_from_the_middle(alpha, rho, phi, delta, DEFAULT_OPTIONS, guess), rel=0.0, abs=1e-11)


@pytest.mark.parametrize("dx", [5e-324, 1e-300, 1e-15])
@pytest.mark.parametrize("dz", [-0.05, 0.05])
def test_near_vertical_segment_just_past_a_node_carves_like_the_reference(dx, dz):
    # the node-index tolerance lets the node sit 0.6e-12 spacings outside the segment; with dx -> 0 (not 0) the
    # interpolation extrapolates far, and the "clearly above" shortcut must not skip what the loop would cut
    i = PILE.heights.size // 2
    xa = PILE.x0 + i * PILE.spacing + 0.6e-12 * PILE.spacing
    z = float(PILE.heights[i]) + 1e-8
    segment = (xa, z, xa + dx, z + dz)
    carver = SurfaceCarver(PILE, 1.5, 0.6, 0.0)
    carver.cut_segment(*segment)
    heights, fill, spilled, removed = _carve_reference(PILE.heights.copy(), PILE.x0, PILE.spacing, 1.5, 0.6, 0.0,
                                                       [segment])
    assert carver.nodes == heights.tolist()
    assert (carver.fill, carver.spilled, carver.removed) == (fill, spilled, removed)
