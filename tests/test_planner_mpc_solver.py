"""The MPC's real-time iteration (``solver="sqp"``) against IPOPT: same plans, IPOPT as fallback, deterministic."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the env ids)
from wheelloader.estimator import Pile, PlanningError
from wheelloader.planner import (
    MPCController,
    PlannerOptions,
    TrajectoryOptimizer,
    cycle_duration,
    default_start,
    make_env_policy,
    verify_plan,
)


@pytest.fixture(scope="module")
def pile() -> Pile:
    return Pile.trapezoid()


def _observation(start) -> np.ndarray:
    obs = np.zeros(17, dtype=np.float32)
    obs[:3] = [start.x, start.z, start.blade_angle]
    return obs


def test_sqp_continues_ipopt_plan_at_the_same_cost(pile):
    """From IPOPT's converged plan the SQP converges at its cost (within 1 %), every constraint satisfied."""
    start = default_start(pile)
    duration = cycle_duration(pile, start)
    ipopt = TrajectoryOptimizer(options=PlannerOptions(intervals=12))
    reference = ipopt.solve("gravel", pile, start, duration)
    assert reference.success
    sqp = TrajectoryOptimizer(options=PlannerOptions(intervals=12, solver="sqp", max_iter=200))
    sqp.warm_start_from(ipopt)
    plan = sqp.solve("gravel", pile, start, duration, warm=True)
    assert plan.status == "Solve_Succeeded"
    assert plan.objective == pytest.approx(reference.objective, rel=0.01)
    assert plan.raw["primal_infeasibility"] <= 1e-6
    # the NumPy check (at 60 Hz between the 12 nodes) says of both plans the same
    assert verify_plan(plan, "gravel", pile).failures == verify_plan(reference, "gravel", pile).failures


def _env_cycle(solver: str) -> tuple[dict, MPCController]:
    env = gym.make("wheelloader/BucketLoading-v0", soil="gravel", sensor_noise=0.0, start_noise=(0.0, 0.0, 0.0))
    obs, _ = env.reset(seed=0)
    policy = make_env_policy(env, solver=solver)
    done, info = False, {}
    while not done:
        obs, _, term, trunc, info = env.step(policy(obs))
        done = term or trunc
    env.close()
    return info, policy


def test_sqp_mpc_digs_the_ipopt_mpc_cycle_at_the_same_cost():
    """In the env, the real-time iteration's executed cycle costs within 1 % of IPOPT's MPC, at the same fill."""
    sqp_info, sqp = _env_cycle("sqp")
    ipopt_info, ipopt = _env_cycle("ipopt")
    for info in (sqp_info, ipopt_info):
        assert not info["stalled"] and info["fill_fraction"] > 0.9
    assert sqp_info["fill_fraction"] == pytest.approx(ipopt_info["fill_fraction"], abs=0.01)

    def per_m3(info):
        return (info["energy_soil"] + info["energy_payload"]) / info["fill_volume"]

    assert per_m3(sqp_info) == pytest.approx(per_m3(ipopt_info), rel=0.01)
    # the first re-plan of the cycle is IPOPT's, the others one QP each, every one checked and used
    assert sqp.history[0].solver == "ipopt"
    rti = [r for r in sqp.history if r.solver == "sqp"]
    assert len(rti) >= len(sqp.history) - 2
    assert all(r.iterations == 1 and r.accepted for r in rti)
    assert all(r.solver == "ipopt" for r in ipopt.history)
    assert all(math.isfinite(r.cpu_seconds) for r in sqp.history)


def test_unusable_sqp_replan_falls_back_to_ipopt(pile, monkeypatch):
    start = default_start(pile)
    mpc = MPCController("gravel", pile, 4.67, replan_every=1)
    assert mpc.optimizer.options.solver == "sqp" and mpc.fallback.options.solver == "ipopt"
    real = mpc.optimizer.solve
    calls = []

    def broken(*args, **kwargs):  # the SQP's first re-plan returns a non-finite plan, its second raises
        calls.append(1)
        plan = real(*args, **kwargs)
        if len(calls) == 1:
            plan.x[:] = np.nan
            return plan
        if len(calls) == 2:
            raise PlanningError("forced SQP failure")
        return plan

    monkeypatch.setattr(mpc.optimizer, "solve", broken)
    obs = _observation(start)
    for _ in range(4):
        mpc(obs)
    assert [r.solver for r in mpc.history] == ["ipopt", "ipopt (fallback)", "ipopt (fallback)", "sqp"]
    # the fallbacks are IPOPT's solves (up to 8 iterations), used when usable; the SQP then goes on from them
    for record in mpc.history[1:3]:
        assert 1 <= record.iterations <= 8 and not record.status.startswith("error")
    assert any(r.accepted for r in mpc.history[1:3])
    assert mpc.history[3].iterations == 1 and mpc.history[3].accepted


def test_sqp_replans_are_deterministic(pile):
    start = default_start(pile)
    runs = []
    for _ in range(2):
        mpc = MPCController("sand", pile, 4.67, replan_every=1)
        obs = _observation(start)
        plans = []
        for k in range(4):
            obs[0] = start.x + 0.01 * k  # the tip moves on between re-plans
            mpc(obs)
            plan = mpc.plan
            plans.append(None if plan is None else np.concatenate([plan.x, plan.z, plan.blade_angle, plan.fill]))
        runs.append(([(r.status, r.iterations, r.accepted, r.solver) for r in mpc.history], plans))
    assert runs[0][0] == runs[1][0]
    assert [r.solver for r in mpc.history][1:] == ["sqp"] * 3
    assert sum(p is not None for p in runs[0][1]) >= 3
    for a, b in zip(runs[0][1], runs[1][1], strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a, b)


def test_solver_choices_are_checked(pile):
    with pytest.raises(PlanningError, match="solver"):
        PlannerOptions(solver="fatrop")
    with pytest.raises(PlanningError, match="qp_solver"):
        PlannerOptions(solver="sqp", qp_solver="qrqp")
    with pytest.raises(PlanningError, match="solver"):
        MPCController("gravel", pile, 4.67, solver="snopt")
    with pytest.raises(PlanningError, match="max_iter"):
        MPCController("gravel", pile, 4.67, max_iter=0)
    ipopt_mpc = MPCController("gravel", pile, 4.67, solver="ipopt")
    assert ipopt_mpc.fallback is None and ipopt_mpc.optimizer.options.max_iter == 8


def test_codegen_compiles_once_and_reloads_from_disk(tmp_path, monkeypatch):
    import casadi as ca

    from wheelloader.planner import codegen

    if codegen.compiler() is None:
        pytest.skip("no C compiler")
    monkeypatch.setenv("WHEELLOADER_NLP_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 2)
    f = ca.Function("wl_test_f", [x], [ca.sin(x[0]) * x[1] ** 2])
    jac = ca.Function("wl_test_jac", [x], [ca.jacobian(f(x), x)])
    first = codegen.compiled({"f": f, "jac": jac}, "wl_test")
    assert first is not None and codegen.LOG[-1]["status"] == "compiled"
    assert codegen.LOG[-1]["compile_cpu_seconds"] >= 0.0
    again = codegen.compiled({"f": f, "jac": jac}, "wl_test")
    assert codegen.LOG[-1]["status"] == "loaded" and codegen.LOG[-1]["library"] == codegen.LOG[-2]["library"]
    point = [0.3, -1.7]
    for key, function in (("f", f), ("jac", jac)):
        np.testing.assert_array_equal(np.array(again[key](point)), np.array(function(point)))
    assert len(list((tmp_path / "compiled").glob("wl_test-*.so"))) == 1


def test_compiled_without_a_compiler_falls_back_to_the_virtual_machine(pile, monkeypatch, tmp_path, caplog):
    from wheelloader.planner import codegen, nlp

    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    # this test's solvers and its failed compile stay out of the process's memo of NLPs
    monkeypatch.setattr(nlp, "_CACHE", {key: type(entry)({**entry, "solvers": dict(entry["solvers"]),
                                                          "derivatives": dict(entry["derivatives"])})
                                        for key, entry in nlp._CACHE.items()})
    start = default_start(pile)
    plans = []
    for compiled in (False, True):
        mpc = MPCController("dirt", pile, 4.67, replan_every=1, options=PlannerOptions(compiled=compiled))
        obs = _observation(start)
        for _ in range(3):
            mpc(obs)
        plans.append((mpc.plan.x.copy(), mpc.plan.z.copy(), [r.solver for r in mpc.history]))
    assert codegen.LOG[-1]["status"] == "failed: no C compiler"
    assert "no C compiler" in caplog.text
    np.testing.assert_array_equal(plans[0][0], plans[1][0])
    np.testing.assert_array_equal(plans[0][1], plans[1][1])
    assert plans[0][2] == plans[1][2]


@pytest.mark.slow
def test_compiled_sqp_replans_equal_the_virtual_machine(pile, tmp_path, monkeypatch):
    """The MPC's SQP with compiled derivatives (about 30 s of CPU to compile) re-plans bit for bit alike."""
    from wheelloader.planner import codegen

    if codegen.compiler() is None:
        pytest.skip("no C compiler")
    start = default_start(pile)
    runs = []
    for compiled in (False, True):
        mpc = MPCController("gravel", pile, 4.67, replan_every=1, options=PlannerOptions(compiled=compiled))
        obs = _observation(start)
        for k in range(4):
            obs[0] = start.x + 0.01 * k
            mpc(obs)
        runs.append(mpc)
    assert codegen.LOG[-1]["status"] in ("compiled", "loaded")
    assert [r.solver for r in runs[1].history][1:] == ["sqp"] * 3
    np.testing.assert_array_equal(runs[0].plan.x, runs[1].plan.x)
    np.testing.assert_array_equal(runs[0].plan.blade_angle, runs[1].plan.blade_angle)
