"""The planner's opt-in physics: the cutting cone (PlannerOptions.cut_angle) and the heel clearance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wheelloader.estimator import BucketPath, Pile, contact_state
from wheelloader.estimator.errors import PlanningError
from wheelloader.planner import PlannerOptions, optimizer_for, verify_plan

CONE = math.radians(55.0)


def _angles_off_blade(path: BucketPath, pile: Pile, deeper_than: float) -> np.ndarray:
    dt = np.diff(path.t)
    vx, vz = np.diff(path.x) / dt, np.diff(path.z) / dt
    th = path.blade_angle[1:]
    along = vx * np.cos(th) + vz * np.sin(th)
    depth = pile.surface_height(path.x[1:]) - path.z[1:]
    moving = (depth > deeper_than) & (np.hypot(vx, vz) > 1e-3)
    return np.arccos(np.clip(along[moving] / np.hypot(vx, vz)[moving], -1.0, 1.0))


def test_options_are_checked():
    with pytest.raises(PlanningError, match="cut_angle"):
        PlannerOptions(cut_angle=math.radians(95.0))
    with pytest.raises(PlanningError, match="cut_depth"):
        PlannerOptions(cut_angle=CONE, cut_depth=-0.1)


def test_the_check_flags_a_bucket_lifted_through_the_soil_on_its_floor():
    pile = Pile.trapezoid()
    t = np.linspace(0.0, 2.0, 121)
    # the tip 30 cm inside the face, blade flat (pointing +x), lifted straight up by 0.4 m: off its blade
    x = np.full_like(t, 0.9)
    z = 0.2 + 0.2 * t
    path = BucketPath(t, x, z, np.zeros_like(t))
    assert "bucket moves off its blade in soil (outside the cutting cone)" in verify_plan(
        path, "gravel", pile, options=PlannerOptions(cut_angle=CONE)).failures
    assert not any("cutting cone" in f for f in verify_plan(path, "gravel", pile).failures)
    # the same lift with the blade pointing up (along the motion) cuts its way: no cone failure
    steep = BucketPath(t, x, z, np.full_like(t, math.radians(80.0)))
    assert not any("cutting cone" in f for f in verify_plan(steep, "gravel", pile,
                                                             options=PlannerOptions(cut_angle=CONE)).failures)


@pytest.mark.parametrize("failure_angle", ["min_n_gamma", "min_weight_force"])
def test_a_plan_with_the_cone_keeps_the_blade_leading(failure_angle):
    """The loop's planner (best checked iterate within the loop's iteration budget) with the cone."""
    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, LOOP_EXIT_MIN_FILL
    from wheelloader.planner import plan_next_cycle

    pile = Pile.trapezoid()
    options = PlannerOptions(cut_angle=CONE, failure_angle=failure_angle, max_iter=BETWEEN_CYCLES_MAX_ITER)
    outcome = plan_next_cycle("gravel", pile, options=options, replan_within_iterations=BETWEEN_CYCLES_MAX_ITER,
                              exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert outcome.success, outcome.message
    path = outcome.path
    check = verify_plan(path, "gravel", pile, options=options, exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert not any("cutting cone" in f for f in check.failures), check.failures
    state = contact_state(path.x, path.z, path.blade_angle, pile, optimizer_for(options=options).bucket)
    assert state.fill_volume[-1] > 0.05  # it digs
    off = _angles_off_blade(path, pile, options.cut_depth)
    assert off.size > 0 and off.max() <= CONE + 0.06
    # without the cone the same planner lets the bucket move further off its blade
    free = plan_next_cycle("gravel", pile, options=PlannerOptions(failure_angle=failure_angle,
                                                                  max_iter=BETWEEN_CYCLES_MAX_ITER),
                           replan_within_iterations=BETWEEN_CYCLES_MAX_ITER, exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert _angles_off_blade(free.path, pile, options.cut_depth).max() > off.max() + 0.1


def _heel_depth(path: BucketPath, pile: Pile, floor_length: float) -> np.ndarray:
    heel_x = path.x - floor_length * np.cos(path.blade_angle)
    heel_z = path.z - floor_length * np.sin(path.blade_angle)
    return pile.surface_height(heel_x) - heel_z


def test_heel_clearance_is_checked():
    with pytest.raises(PlanningError, match="heel_clearance"):
        PlannerOptions(heel_clearance=float("nan"))
    pile = Pile.trapezoid()
    t = np.linspace(0.0, 2.0, 121)
    # 10 cm under the flat top, blade tilted up 20 deg: the heel trails 0.45 sin(20 deg) = 0.15 m lower still
    x = 2.0 + 0.3 * t
    z = np.full_like(t, 0.9)
    path = BucketPath(t, x, z, np.full_like(t, math.radians(20.0)))
    buried = "bucket's heel in the soil (below the heel clearance)"
    assert buried in verify_plan(path, "gravel", pile, options=PlannerOptions(heel_clearance=0.0)).failures
    assert buried not in verify_plan(path, "gravel", pile).failures


def test_a_plan_with_heel_clearance_keeps_the_heel_out():
    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, LOOP_EXIT_MIN_FILL
    from wheelloader.planner import plan_next_cycle
    from wheelloader.planner.verify import HEEL_TOLERANCE

    # a 20 deg face: here the free planner digs with its heel ~0.2 m in the soil (on the default 30 deg pile it
    # has kept the heel at the surface since the planner's soil and pile are quantised, so no contrast there)
    pile = Pile.trapezoid(angle=math.radians(20.0))
    options = PlannerOptions(heel_clearance=0.0, failure_angle="min_weight_force", max_iter=BETWEEN_CYCLES_MAX_ITER)
    outcome = plan_next_cycle("gravel", pile, options=options, replan_within_iterations=BETWEEN_CYCLES_MAX_ITER,
                              exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert outcome.success, outcome.message
    floor = optimizer_for(options=options).bucket.floor_length
    assert _heel_depth(outcome.path, pile, floor).max() <= HEEL_TOLERANCE
    state = contact_state(outcome.path.x, outcome.path.z, outcome.path.blade_angle, pile,
                          optimizer_for(options=options).bucket)
    assert state.fill_volume[-1] > 0.05
    # the same planner without it buries the heel on this pile
    free = plan_next_cycle("gravel", pile, options=PlannerOptions(failure_angle="min_weight_force",
                                                                  max_iter=BETWEEN_CYCLES_MAX_ITER),
                           replan_within_iterations=BETWEEN_CYCLES_MAX_ITER, exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert _heel_depth(free.path, pile, floor).max() > HEEL_TOLERANCE + 0.01


def test_end_blade_angle_is_checked():
    with pytest.raises(PlanningError, match="end_blade_angle"):
        PlannerOptions(end_blade_angle=math.radians(80.0))  # beyond the blade-angle limits (75 deg)
    pile = Pile.trapezoid()
    t = np.linspace(0.0, 1.0, 61)
    path = BucketPath(t, -0.5 + 0.2 * t, np.full_like(t, 0.3), np.zeros_like(t))  # in the air, blade flat
    flat = "bucket not curled at the end (below the end blade angle)"
    assert flat in verify_plan(path, "gravel", pile, options=PlannerOptions(end_blade_angle=math.radians(45))).failures
    assert flat not in verify_plan(path, "gravel", pile).failures


def test_a_plan_with_an_end_blade_angle_ends_curled():
    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, LOOP_EXIT_MIN_FILL
    from wheelloader.planner import plan_next_cycle

    options = PlannerOptions(end_blade_angle=math.radians(45.0), max_iter=BETWEEN_CYCLES_MAX_ITER)
    outcome = plan_next_cycle("gravel", Pile.trapezoid(), options=options,
                              replan_within_iterations=BETWEEN_CYCLES_MAX_ITER, exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert outcome.success, outcome.message
    assert outcome.path.blade_angle[-1] >= math.radians(45.0) - 0.02


def test_curl_out_intervals_are_checked():
    with pytest.raises(PlanningError, match="curl_out_intervals"):
        PlannerOptions(curl_out_intervals=-1)
    with pytest.raises(PlanningError, match="curl_out_intervals"):
        PlannerOptions(intervals=20, curl_out_intervals=10)
    with pytest.raises(PlanningError, match="curl_out_intervals"):
        PlannerOptions(curl_out_intervals=True)
    # without an end blade angle there is no curl-out phase
    assert PlannerOptions(curl_out_intervals=8).curl_out == 0
    assert PlannerOptions(curl_out_intervals=8, end_blade_angle=math.radians(45.0)).curl_out == 8


def test_a_plan_with_heel_clearance_and_curl_out_ends_curled_with_the_heel_out():
    from wheelloader.adaptation import BETWEEN_CYCLES_MAX_ITER, LOOP_EXIT_MIN_FILL
    from wheelloader.planner import plan_next_cycle
    from wheelloader.planner.verify import HEEL_TOLERANCE

    # a 20 deg face: here the free planner digs with its heel ~0.2 m in the soil (on the default 30 deg pile it
    # has kept the heel at the surface since the planner's soil and pile are quantised, so no contrast there)
    pile = Pile.trapezoid(angle=math.radians(20.0))
    options = PlannerOptions(heel_clearance=0.0, end_blade_angle=math.radians(45.0), curl_out_intervals=8,
                             failure_angle="min_weight_force", max_iter=BETWEEN_CYCLES_MAX_ITER)
    outcome = plan_next_cycle("gravel", pile, options=options, replan_within_iterations=BETWEEN_CYCLES_MAX_ITER,
                              exit_min_fill=LOOP_EXIT_MIN_FILL)
    assert outcome.success, outcome.message
    path = outcome.path
    assert path.blade_angle[-1] >= math.radians(45.0) - 0.02
    floor = optimizer_for(options=options).bucket.floor_length
    assert _heel_depth(path, pile, floor).max() <= HEEL_TOLERANCE  # in the curl-out too
    state = contact_state(path.x, path.z, path.blade_angle, pile, optimizer_for(options=options).bucket)
    assert state.fill_volume[-1] > 0.1  # the bucket fills (0.2 m^3 nominal)


def test_the_mpc_scales_the_curl_out_to_its_horizon():
    from wheelloader.planner import MPCController

    def curl_out(intervals: int, base: int) -> int:
        options = PlannerOptions(end_blade_angle=math.radians(45.0), curl_out_intervals=base)
        return MPCController("gravel", Pile.trapezoid(), 4.0, intervals=intervals,
                             options=options).optimizer.options.curl_out_intervals

    assert curl_out(12, 8) == 2  # the same share of the horizon: round(8 * 12 / 40)
    # capped below half the horizon, also for an odd number of intervals (19 of 40 -> 6 of 13 would not be)
    assert curl_out(13, 19) == 5
    assert curl_out(12, 19) == 5
