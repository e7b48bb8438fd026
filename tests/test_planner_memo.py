"""planner.memo.RememberedPlanner: the same soil and pile are planned once; copies, never the kept object."""

from __future__ import annotations

import numpy as np
import pytest

from wheelloader.estimator import Pile, preset
from wheelloader.planner import PlanOutcome, bezier_on_face
from wheelloader.planner.memo import RememberedPlanner


class _Counting:
    """A fake planner: a Bezier path on the face, the call count in the message."""

    def __init__(self, controller=None):
        self.calls = 0
        self.controller = controller

    def __call__(self, params, pile):
        self.calls += 1
        return PlanOutcome(bezier_on_face(pile), True, f"call {self.calls}", 0.5, self.controller)


def test_the_same_soil_and_pile_are_planned_once_and_each_caller_gets_its_own_copy():
    inner = _Counting()
    planner = RememberedPlanner(inner)
    first = planner("sand", Pile.trapezoid())
    first.seconds = 99.0
    first.first_failures.append("spoilt")  # a caller changing its copy changes nothing kept
    second = planner(preset("sand"), Pile.trapezoid())  # the same soil given another way
    assert inner.calls == 1 and planner.hits == 1
    assert second.message == "call 1" and second.seconds < 99.0 and second.first_failures == []
    assert np.array_equal(second.path.x, bezier_on_face(Pile.trapezoid()).x)


def test_another_soil_or_pile_by_one_bit_is_planned_again():
    inner = _Counting()
    planner = RememberedPlanner(inner)
    pile = Pile.trapezoid()
    planner("sand", pile)
    heights = pile.heights.copy()
    heights[50] = np.nextafter(heights[50], np.inf)
    planner("sand", pile.with_heights(heights))
    soil = preset("sand")
    planner(soil.__class__(**{**soil.to_dict(), "phi": np.nextafter(soil.phi, 1.0)}), pile)
    assert inner.calls == 3 and planner.hits == 0


def test_outcomes_with_a_controller_are_not_kept_and_the_oldest_goes_first():
    with_controller = _Counting(controller=lambda obs: obs)
    planner = RememberedPlanner(with_controller)
    planner("sand", Pile.trapezoid())
    planner("sand", Pile.trapezoid())
    assert with_controller.calls == 2
    inner = _Counting()
    planner = RememberedPlanner(inner, size=2)
    for soil in ("sand", "gravel", "dirt", "sand"):  # "sand" was dropped when "dirt" came
        planner(soil, Pile.trapezoid())
    assert inner.calls == 4
    with pytest.raises(TypeError):
        RememberedPlanner("not a planner")
