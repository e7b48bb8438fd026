"""The planner's opt-in ``descend_clearance`` (#33): the tip moves down only near the surface, never onto the pile
from above (the MPM plant's plunge: 143 kN, 2.4x the predicted energy; the force model has no force for it)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wheelloader.estimator import BucketPath, Pile
from wheelloader.estimator.errors import PlanningError
from wheelloader.planner import PlannerOptions, verify_plan
from wheelloader.planner.verify import DESCEND_SPEED_TOLERANCE, DESCEND_TOLERANCE

PLUNGE = "tip comes down onto the pile from above (above the descend clearance)"


def _descents_from(path: BucketPath, pile: Pile) -> np.ndarray:
    """Heights above the surface [m] from which a step moves the tip down."""
    height = path.z - pile.surface_height(path.x)
    vz = np.diff(path.z) / np.diff(path.t)
    return height[:-1][vz < -DESCEND_SPEED_TOLERANCE]


def test_options_are_checked():
    with pytest.raises(PlanningError, match="descend_clearance"):
        PlannerOptions(descend_clearance=-0.1)
    assert PlannerOptions(descend_clearance=0.1).descend_clearance == 0.1


def test_the_check_flags_a_tip_coming_down_onto_the_pile_from_above():
    pile = Pile.trapezoid()
    t = np.linspace(0.0, 2.0, 121)
    # over the face at x = 0.9 m, from 0.9 m down to the surface (gravel seed 1, cycle 4 of the held run)
    x = np.full_like(t, 0.9)
    surface = float(pile.surface_height(0.9))
    z = 0.9 - (0.9 - surface - 0.01) * t / 2.0
    path = BucketPath(t, x + 1e-4 * t, z, np.zeros_like(t))
    options = PlannerOptions(descend_clearance=0.1)
    assert PLUNGE in verify_plan(path, "gravel", pile, options=options).failures
    assert PLUNGE not in verify_plan(path, "gravel", pile).failures
    # the last 10 cm of the same descent is allowed
    near = z - surface < 0.1 + DESCEND_TOLERANCE
    low = BucketPath(t[near] - t[near][0], x[near] + 1e-4 * t[near], z[near], np.zeros(int(near.sum())))
    assert PLUNGE not in verify_plan(low, "gravel", pile, options=options).failures


def test_a_loop_plan_with_the_clearance_never_comes_down_from_above():
    """The MPM loop's planner settings (benchmarks/loop_mpm.sh) on the fresh pile, with the clearance."""
    from wheelloader.loop_planner import default_planner

    pile = Pile.trapezoid()
    plan = default_planner(failure_angle="min_weight_force", heel_clearance=0.0, end_blade_angle=math.radians(55.0),
                           curl_out_intervals=8, midpoints=False, objective="kept_per_energy",
                           descend_clearance=0.1)
    outcome = plan("gravel", pile)
    assert outcome.success, outcome.message
    assert outcome.check.details["descend_steps"] == 0
    assert np.all(_descents_from(outcome.path, pile) <= 0.1 + DESCEND_TOLERANCE)
