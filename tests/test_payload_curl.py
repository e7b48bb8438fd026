"""The payload's curl dependence (``PayloadOptions.curl_gain``): the heaped capacity grows with the blade angle
as the tip leaves the soil; the estimator, both envs and the planner agree on it, and ``fit_payload`` recovers it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.config import pile_toe
from wheelloader.envs.scripted import PathTracker
from wheelloader.estimator import Bucket, CycleLog, ParameterError, Pile, fit_payload, paper_paths
from wheelloader.estimator.kinematics import contact_state
from wheelloader.estimator.paths import default_path
from wheelloader.estimator.payload import (
    MIN_HEAP,
    PayloadOptions,
    exit_angle_profile,
    kept_fill,
    kept_volume,
    kept_volume_float,
    payload_contact_state,
    removed_volume,
)

CURL = PayloadOptions(0.8, 0.45, 2.5, 0.3)


def test_exit_angle_profile_holds_the_angle_after_the_tip_leaves():
    angle = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    depth = np.array([0.0, 0.1, 0.2, 0.0, 0.0, 0.1, -0.1])
    np.testing.assert_array_equal(exit_angle_profile(angle, depth), [0.0, 1.0, 2.0, 2.0, 2.0, 5.0, 5.0])
    # never in soil: the current angle
    np.testing.assert_array_equal(exit_angle_profile(angle, np.zeros(7)), angle)


def test_heaped_capacity_follows_the_exit_angle():
    cap = 0.2
    for angle in (-0.2, 0.0, 0.3, math.radians(45.0)):
        heaped = (CURL.heap_factor + CURL.curl_gain * math.sin(angle)) * cap
        assert float(CURL.heaped(cap, angle)) == pytest.approx(heaped, rel=1e-12)
        # far past the heap the kept soil is the heaped capacity; the float twin is the same formula
        assert float(kept_volume(50.0, cap, CURL, 0.0, angle)) == pytest.approx(heaped, rel=1e-6)
        assert kept_volume_float(0.1, cap, CURL, 0.0, angle) == pytest.approx(
            float(kept_volume(0.1, cap, CURL, 0.0, angle)), rel=1e-12)
    # curled further at the exit: keeps more of the same removed volume
    assert kept_volume_float(0.2, cap, CURL, 0.0, 0.5) > kept_volume_float(0.2, cap, CURL, 0.0, 0.1)
    # floored: a gain that would empty the heap
    steep = PayloadOptions(0.8, 0.1, 2.5, 2.0)
    assert float(steep.heaped(cap, -1.0)) == pytest.approx(MIN_HEAP * cap)
    # curl_gain 0 ignores the angle (the previous model, to the bit)
    plain = PayloadOptions(0.8, 0.45, 2.5)
    assert kept_volume_float(0.15, cap, plain, 0.0, 0.7) == kept_volume_float(0.15, cap, plain)


@settings(max_examples=60, deadline=None)
@given(removed=st.floats(0.0, 0.4), angle=st.floats(-0.5, 1.2))
def test_removed_volume_inverts_the_curled_kept_volume(removed, angle):
    kept = kept_volume_float(removed, 0.2, CURL, 0.0, angle)
    assert removed_volume(kept, 0.2, CURL, 0.0, angle) == pytest.approx(removed, rel=1e-7, abs=1e-12)


def test_casadi_kept_volume_is_the_numpy_one():
    import casadi as ca

    v, a = ca.SX.sym("v"), ca.SX.sym("a")
    fn = ca.Function("kept", [v, a], [kept_volume(v, 0.2, CURL, 0.0, a), ca.gradient(kept_volume(v, 0.2, CURL, 0.0,
                                                                                                  a), a)])
    for removed, angle in ((0.05, 0.1), (0.2, 0.4), (0.3, -0.1)):
        value, grad = fn(removed, angle)
        assert float(value) == pytest.approx(float(kept_volume(removed, 0.2, CURL, 0.0, angle)), rel=1e-12)
        assert float(grad) > 0.0


def test_settings_round_trip_and_are_checked():
    assert "curl_gain" not in PayloadOptions(0.8, 0.45, 2.5).to_dict()  # older readers read the rest
    assert PayloadOptions.from_dict(CURL.to_dict()) == CURL
    with pytest.raises(ParameterError, match="curl_gain"):
        PayloadOptions(curl_gain=3.0)
    log = _env_log()
    with pytest.raises(ParameterError, match="blade_angle"):
        kept_fill(log.contact_state(fill="model"), log.bucket.capacity, CURL)
    with pytest.raises(ParameterError, match="samples"):
        fit_payload([log], samples="middle")


def _env_log(payload: PayloadOptions = CURL, seed: int = 3) -> CycleLog:
    """The paper's Bezier path tracked to the cycle's end in a noise-free ``fee-payload`` env with ``payload``."""
    env = BucketLoadingEnv(force_model="fee-payload", payload=payload, sensor_noise=0.0)
    tracker = PathTracker(default_path(pile_toe(env.cfg.pile), rate=env.cfg.control_rate), env.cfg.loader,
                          env.cfg.control_rate)
    obs, _ = env.reset(seed=seed)
    for _ in range(900):
        obs, _, terminated, truncated, _ = env.step(tracker(obs))
        if terminated or truncated:
            break
    return env.last_cycle_log()


def test_env_fill_is_the_estimators_curled_kept_soil():
    log = _env_log()
    state = payload_contact_state(log, CURL)
    np.testing.assert_allclose(log.fill_volume, state.carried_volume, rtol=1e-9, atol=1e-12)
    angle = exit_angle_profile(log.path.blade_angle, state.depth)
    assert kept_fill(log.contact_state(fill="model"), log.bucket.capacity, CURL,
                     blade_angle=log.path.blade_angle) == pytest.approx(log.fill_volume[-1], rel=1e-9)
    # the curl mattered: the plain heap keeps another amount of the same removed soil
    plain = kept_volume(state.carve.removed_history[-1], log.bucket.capacity, replace(CURL, curl_gain=0.0))
    assert abs(float(plain) - log.fill_volume[-1]) > 1e-4
    assert np.ptp(angle) > 0.1


def _synthetic_logs(truth: PayloadOptions) -> list[CycleLog]:
    """The paper's paths on the default pile, each with the kept fill ``truth`` predicts for it."""
    pile, bucket = Pile.trapezoid(), Bucket()
    logs = []
    for path in paper_paths():
        for lift in (0.0, 0.25):  # the same cut curled further at the end: another exit angle
            p = replace(path, blade_angle=path.blade_angle + lift * np.linspace(0.0, 1.0, path.t.size) ** 2)
            state = contact_state(p.x, p.z, p.blade_angle, pile, bucket)
            kept = kept_volume(state.carve.removed_history, bucket.capacity, truth, 0.0,
                               exit_angle_profile(p.blade_angle, state.depth))
            zeros = np.zeros(p.t.size)
            logs.append(CycleLog(p, zeros, zeros, pile, bucket, fill_volume=np.asarray(kept)))
    return logs


def test_fit_payload_recovers_the_curl_gain():
    truth = PayloadOptions(0.75, 0.5, 3.0, 0.25)
    logs = _synthetic_logs(truth)
    start = PayloadOptions(0.9, 0.7, 2.0)
    for samples in ("path", "end"):
        free = ("retention", "heap_factor", "sharpness", "curl_gain") if samples == "path" else (
            "heap_factor", "curl_gain")
        fitted = fit_payload(logs, free=free, samples=samples,
                             initial=start if samples == "path" else replace(truth, heap_factor=0.7, curl_gain=0.0))
        for name in free:
            assert getattr(fitted, name) == pytest.approx(getattr(truth, name), rel=1e-4, abs=1e-6), (samples, name)
    # the default leaves the curl out
    assert fit_payload(logs, initial=start).curl_gain == 0.0


def test_fit_payload_skips_logs_that_keep_more_than_they_removed():
    truth = PayloadOptions(0.75, 0.5, 3.0)
    logs = _synthetic_logs(truth)
    bad = replace(logs[0], fill_volume=logs[0].fill_volume * 3.0)  # "keeps" more than its carving removed
    removed = logs[0].contact_state(fill="model").carve.removed_history[-1]
    assert bad.fill_volume[-1] > 0.9 * removed
    start = PayloadOptions(0.9, 0.7, 2.0)
    skipped = fit_payload([bad, *logs], initial=start, max_kept_ratio=0.9)
    assert skipped.retention == pytest.approx(0.75, rel=1e-4)
    assert fit_payload([bad, *logs], initial=start).retention != pytest.approx(0.75, rel=1e-2)


def test_planner_plans_with_the_curled_payload_and_its_check_agrees():
    """The NLP counts the kept soil at its end node's blade angle, the NumPy check at the exit's: within the
    NLP's smooth surface (10 %, as for the plain payload), and the check's fill is the estimator's."""
    from wheelloader.planner import PlannerOptions, plan_next_cycle

    pile, cap = Pile.trapezoid(), 0.2
    options = PlannerOptions(force_model="fee-payload", payload=CURL, max_iter=130, midpoints=True)
    out = plan_next_cycle("gravel", pile, options=options, mpc=False)
    assert out.success and out.check.ok, out.message
    state = contact_state(out.path.x, out.path.z, out.path.blade_angle, pile, Bucket())
    exit_angle = exit_angle_profile(out.path.blade_angle, state.depth)[-1]
    assert out.check.fill == pytest.approx(float(kept_volume(out.check.carved, cap, CURL, 0.0, exit_angle)),
                                           rel=1e-9)
    nlp_end = float(kept_volume(out.plan.fill[-1], cap, CURL, 0.0, out.plan.blade_angle[-1]))
    assert out.check.fill == pytest.approx(nlp_end, rel=0.1)


def test_the_kept_objective_sees_the_blade_angle_as_the_tip_leaves_the_soil():
    """With the MPM loop's curl-out phase (end blade angle 55 deg, 8 intervals) the end node is curled well above
    the soil: the NLP's and the check's kept soil take the angle at the last node in soil, as the payload's
    exit-angle profile does (and the fixed path's kept target), not the end node's."""
    from wheelloader.loop_planner import default_planner

    pile, cap = Pile.trapezoid(), 0.2
    plan = default_planner(failure_angle="min_weight_force", heel_clearance=0.0, end_blade_angle=math.radians(55.0),
                           curl_out_intervals=8, midpoints=False, objective="kept_per_energy", payload=CURL)
    out = plan("gravel", pile)
    assert out.success, out.message
    nodes = out.plan
    exit_angle = float(exit_angle_profile(nodes.blade_angle, pile.surface_height(nodes.x) - nodes.z)[-1])
    assert exit_angle < nodes.blade_angle[-1] - math.radians(10.0)
    nlp_kept = nodes.raw["kept_terms"]["kept"]
    assert nlp_kept == pytest.approx(float(kept_volume(nodes.fill[-1], cap, CURL, 0.0, exit_angle)), rel=0.05)
    at_end = float(kept_volume(nodes.fill[-1], cap, CURL, 0.0, nodes.blade_angle[-1]))
    assert abs(nlp_kept / at_end - 1.0) > 0.05
    kept_percent = round(100 * float(kept_volume(out.check.carved, cap, CURL, 0.0, exit_angle)) / cap)
    assert f"kept {kept_percent}%" in out.message
