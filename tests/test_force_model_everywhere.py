"""One force model everywhere: for every name of ``FORCE_MODELS`` the estimator (NumPy arrays), the env (one
sample per step, single and batched) and the planner (CasADi) compute the same forces and the same fill."""

from __future__ import annotations

import pickle
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest

import wheelloader.envs  # noqa: F401  (registers the ids)
from wheelloader.envs import BucketLoadingEnv
from wheelloader.envs.config import pile_toe
from wheelloader.envs.scripted import PathTracker
from wheelloader.envs.vector import BucketLoadingVectorEnv
from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    DEFAULT_PAYLOAD,
    FORCE_MODELS,
    ParameterError,
    PayloadOptions,
    contact_state,
    default_path,
    predict,
    soil_forces,
)
from wheelloader.estimator.force_models import (
    PAYLOAD_MODELS,
    PLANT_FORCE_MODELS,
    check_force_model,
    cycle_contact_state,
    model_options_for,
)
from wheelloader.estimator.learned import default_learned_model, learned_forces, learned_inputs
from wheelloader.estimator.paths import BucketPath
from wheelloader.estimator.payload import kept_volume

MAIN_ID = "wheelloader/BucketLoading-v0"


def _dig(name: str, seed: int = 3, **settings):
    """Track the paper's Bezier path in a noise-free env of force model ``name`` to the cycle's end; the
    per-step record, the carved volume and the env."""
    env = BucketLoadingEnv(force_model=name, sensor_noise=0.0, **settings)
    path = default_path(pile_toe(env.cfg.pile), rate=env.cfg.control_rate)
    tracker = PathTracker(path, env.cfg.loader, env.cfg.control_rate)
    obs, _ = env.reset(seed=seed)
    carved, infos = [0.0], []
    for _ in range(900):
        obs, _, terminated, truncated, info = env.step(tracker(obs))
        infos.append(info)
        carved.append(info["carved_volume"])
        if terminated or truncated:
            break
    record = env.episode_record()
    assert not any(i["stalled"] for i in infos)
    return env, record, np.asarray(carved), infos


def _estimator_forces(name: str, env, record, carved):
    """The estimator's forces (arrays) on the env's samples: its geometry, the carved fill as surcharge and,
    where the model carries a payload, the env's kept soil and its acceleration this step."""
    cfg = env.cfg
    x, z, th = record["x"], record["z"], record["blade_angle"]
    v = np.vstack([[0.0, 0.0], np.column_stack([np.diff(x), np.diff(z)]) / cfg.dt])  # realised, from rest
    acc = np.vstack([[0.0, 0.0], np.diff(v, axis=0) / cfg.dt])
    state = contact_state(x, z, th, env.start_pile, cfg.bucket, slope_window=cfg.slope_window, fill_volume=carved,
                          acceleration=acc)
    payload = check_force_model(name, cfg.payload)
    if payload is not None:
        state = replace(state, carried_volume=record["fill"])
    forces = soil_forces(env.soil, state, cfg.bucket, model_options_for(name, DEFAULT_OPTIONS))
    if name == "fee-learned":  # the network at the env's inputs (learned_inputs), the speed the realised one
        path = BucketPath(np.arange(x.size) * cfg.dt, x, z, th)
        inputs = learned_inputs(state, path, cfg.bucket, env.soil)
        inputs[:, 7] = np.hypot(v[:, 0], v[:, 1]) / np.sqrt(9.81 * cfg.bucket.floor_length)
        model = default_learned_model()
        r = model.correction(inputs) * env.soil.gamma * 9.81 * cfg.bucket.width * cfg.bucket.floor_length ** 2
        forces = replace(forces, tangential=forces.tangential + r[:, 0], normal=forces.normal + r[:, 1])
    return forces


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_env_single_samples_are_the_estimators_arrays(name):
    env, record, carved, infos = _dig(name)
    assert len(record["x"]) == len(carved) > 100
    forces = _estimator_forces(name, env, record, carved)
    np.testing.assert_allclose(record["true_F_T"], forces.tangential, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(record["true_F_N"], forces.normal, rtol=1e-9, atol=1e-6)
    assert np.array_equal(record["flags"], forces.flags)
    # the env's fill is the model's fill of the path: the carving (fee) or the payload's kept soil of it
    log = env.last_cycle_log()
    state = cycle_contact_state(log, name, env.cfg.payload, env.cfg.slope_window, "model")
    model_fill = state.fill_volume if state.carried_volume is None else state.carried_volume
    np.testing.assert_allclose(log.fill_volume, model_fill, rtol=1e-9, atol=1e-12)
    assert infos[-1]["fill_volume"] == pytest.approx(model_fill[-1], rel=1e-9)
    # and predict() on the cycle log (the path's acceleration and speed from central differences, not the env's
    # step) reproduces the env's forces: within 0.1 % of the mean F_R (measured: exact for fee, 0.009 % for
    # fee-payload), 0.5 % for fee-learned (measured 0.11 %: the speed, an input of its correction)
    pred = predict(env.soil, log, force_model=name)
    gap = np.hypot(pred.tangential - record["true_F_T"], pred.normal - record["true_F_N"])
    bound = 5e-3 if name == "fee-learned" else 1e-3
    assert np.sqrt(np.mean(gap**2)) < bound * np.mean(np.hypot(record["true_F_T"], record["true_F_N"]))


def test_payload_fill_is_kept_soil_and_its_weight_stays_after_exit():
    _, fee, fee_carved, fee_infos = _dig("fee")
    env, rec, carved, infos = _dig("fee-payload")
    cap = env.cfg.bucket.capacity
    # same path, same carving: the payload keeps part of what the FEE's fill counts, up to its heaped capacity
    np.testing.assert_allclose(carved, fee_carved[:carved.size], rtol=1e-9, atol=1e-12)
    assert 0.0 < rec["fill"][-1] < carved[-1]
    assert rec["fill"][-1] <= DEFAULT_PAYLOAD.heap_factor * cap + 1e-12
    last = infos[-1]
    assert last["fill_fraction"] == pytest.approx(rec["fill"][-1] / cap)
    assert last["carved_volume"] == pytest.approx(carved[-1])
    # reward_fill sums to the kept fill per capacity (the fill gained each step)
    assert sum(i["reward_fill"] for i in infos) == pytest.approx(rec["fill"][-1] / cap, rel=1e-9)
    # after the tip left the soil the FEE's force is 0, the payload's is the kept soil's weight (and inertia)
    # (a cycle ends with the tip out of the soil; its inertia is within the loader's acceleration, 2 m/s^2 a
    # component, so within 0.29 of the weight)
    assert env.cycle_ends == ("exit",) and infos[-1]["depth"] <= 0.0 and fee_infos[-1]["depth"] <= 0.0
    weight = env.soil.gamma * 9.81 * rec["fill"][-1]
    assert np.hypot(rec["true_F_T"][-1], rec["true_F_N"][-1]) == pytest.approx(weight, rel=0.29)
    assert fee["true_F_T"][-1] == 0.0 and fee["true_F_N"][-1] == 0.0


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_gym_make_pickle_check_env_and_vector_env_take_the_model(name):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(MAIN_ID, force_model=name)
    check_env(env.unwrapped, skip_render_check=True)
    base = env.unwrapped
    assert base.cfg.force_model == name
    clone = pickle.loads(pickle.dumps(base))
    assert clone.cfg.force_model == name and clone.cfg.payload == base.cfg.payload
    vec = gym.make_vec(MAIN_ID, num_envs=2, force_model=name)
    assert vec.unwrapped.cfg.force_model == name
    _, info = vec.reset(seed=0)[0], vec.step(np.zeros((2, 3), dtype=np.float32))[-1]
    assert "carved_volume" in info and info["_carved_volume"].all()
    rllib = BucketLoadingEnv({"force_model": name})
    assert rllib.cfg.force_model == name
    meta = base.cfg.to_dict()
    assert ("force_model" in meta) == (name != "fee")


def test_payload_settings_are_checked():
    cfg = BucketLoadingEnv(force_model="fee-payload", payload={"retention": 0.5}).cfg
    assert cfg.payload == PayloadOptions(retention=0.5)
    assert BucketLoadingEnv(force_model="fee-payload").cfg.payload == DEFAULT_PAYLOAD
    assert BucketLoadingEnv().cfg.payload is None
    assert BucketLoadingEnv(force_model="fee-learned").cfg.payload == default_learned_model().payload
    with pytest.raises(ParameterError, match="fee-payload"):
        BucketLoadingEnv(payload={"retention": 0.5})
    with pytest.raises(ParameterError, match="force_model"):
        BucketLoadingEnv(force_model="fea")
    with pytest.raises(ParameterError, match="unknown key"):
        BucketLoadingEnv(force_model="fee-payload", payload={"retension": 0.5})
    with pytest.raises(ParameterError, match="retention"):
        BucketLoadingVectorEnv(num_envs=2, force_model="fee-payload", payload={"retention": 0.0})


def test_batched_fill_is_the_kept_volume_of_its_removed_volume():
    vec = BucketLoadingVectorEnv(num_envs=3, force_model="fee-payload", sensor_noise=0.0)
    vec.reset(seed=1)
    act = np.tile(np.array([[0.6, -0.05, 0.0]], dtype=np.float32), (3, 1))
    for _ in range(60):
        _, _, _, _, info = vec.step(act)
    cap = vec.cfg.bucket.capacity
    assert np.all(info["carved_volume"] > 0.0)
    # the records log the kept soil, which is less than the carved volume and at most the heaped capacity
    records = vec.call("episode_record", current=True)
    assert [r["fill"][-1] for r in records] == info["fill_volume"].tolist()
    np.testing.assert_array_less(info["fill_volume"], info["carved_volume"] + 1e-12)
    assert np.all(info["fill_volume"] <= kept_volume(np.full(3, 10.0), cap, DEFAULT_PAYLOAD) + 1e-12)


def _casadi_function(name: str, bucket):
    """The planner's CasADi force model of ``name`` as a function of the soil vector and the contact (the carved
    and kept fill [m^3], the blade angle and the tip velocity: the learned correction's inputs)."""
    import casadi as ca

    from wheelloader.planner import PlannerOptions
    from wheelloader.planner.casadi_model import casadi_forces, casadi_learned

    options = PlannerOptions(force_model=name)
    soil, vertical, rho, alpha, carved, kept, th, vx, vz = (
        ca.SX.sym(n, k) for n, k in (("soil", 7), ("v", 1), ("rho", 1), ("alpha", 1), ("carved", 1), ("kept", 1),
                                     ("th", 1), ("vx", 1), ("vz", 1)))
    weight = soil[0] * 9.81
    out = casadi_forces(soil, vertical, rho, alpha, weight * carved, bucket, options.model_options, weight * kept)
    f_t, f_n = out["F_T"], out["F_N"]
    if name == "fee-learned":
        c_t, c_n = casadi_learned(soil, out["depth"], rho, alpha, th, carved, kept, vx, vz, bucket)
        f_t, f_n = f_t + c_t, f_n + c_n
    grad = ca.jacobian(ca.vertcat(f_t, f_n), ca.vertcat(vertical, rho, kept, vx))
    return ca.Function("f", [soil, vertical, rho, alpha, carved, kept, th, vx, vz], [f_t, f_n, grad]), options


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_planner_casadi_model_is_the_estimators(name):
    """On the paper's paths: in soil within the planner's smoothing (as for the FEE, 3 % of the peak), out of
    the soil (5 mm above it and more) the same carried weight; finite exact derivatives everywhere."""
    from wheelloader.estimator import Bucket, Pile, paper_paths, preset, soil_vector

    pile, bucket, soil = Pile.trapezoid(), Bucket(), preset("gravel")
    fn, options = _casadi_function(name, bucket)
    payload = options.force_payload
    assert payload == check_force_model(name, None)
    for path in paper_paths():
        # the path, then lifted out of the pile with what it carved (the payload's weight after the exit)
        x = np.concatenate([path.x, np.full(20, path.x[-1])])
        z = np.concatenate([path.z, path.z[-1] + np.linspace(0.01, 0.3, 20)])
        th = np.concatenate([path.blade_angle, np.full(20, path.blade_angle[-1])])
        t = np.concatenate([path.t, path.t[-1] + np.arange(1, 21) * np.mean(np.diff(path.t))])
        state = contact_state(x, z, th, pile, bucket)
        if payload is not None:
            state = replace(state, carried_volume=kept_volume(state.carve.removed_history, bucket.capacity, payload))
        ref = soil_forces(soil, state, bucket, options.model_options)
        lifted = BucketPath(t, x, z, th)
        if name == "fee-learned":
            lf = learned_forces(default_learned_model(), state, lifted, bucket, soil)
            ref = replace(ref, tangential=ref.tangential + lf.tangential, normal=ref.normal + lf.normal,
                          resultant=np.hypot(ref.tangential + lf.tangential, ref.normal + lf.normal))
        kept = state.fill_volume if state.carried_volume is None else state.carried_volume
        vertical = pile.surface_height(x) - z
        vx, vz, _ = lifted.velocity()
        rows = [np.atleast_2d(v) for v in (vertical, state.rho, state.alpha, state.fill_volume, kept, th, vx, vz)]
        f_t, f_n, grad = fn.map(x.size)(soil_vector(soil, bucket.edge_thickness), *rows)
        f_t, f_n = np.asarray(f_t).ravel(), np.asarray(f_n).ravel()
        assert np.all(np.isfinite(np.asarray(grad)))
        valid = ref.flags == 0
        gap = np.max(np.hypot(f_t - ref.tangential, f_n - ref.normal)[valid]) / np.max(ref.resultant)
        assert gap < 0.03, f"{name} {path.name}: CasADi vs NumPy gap {gap:.3%}"
        out = vertical < -0.005
        assert out[-1]
        np.testing.assert_allclose(f_t[out], ref.tangential[out], rtol=1e-4, atol=1.0)
        np.testing.assert_allclose(f_n[out], ref.normal[out], rtol=1e-4, atol=1.0)
        if payload is not None:
            assert ref.resultant[-1] > 500.0  # the kept soil's weight


@pytest.mark.parametrize("name", FORCE_MODELS)
def test_planner_plans_and_checks_with_the_model(name):
    """A plan with ``PlannerOptions(force_model=name)``: the NLP's fill at the end is the model's fill of its
    carved volume, and the NumPy check (the estimator's model) agrees with it and passes."""
    from wheelloader.estimator import Pile
    from wheelloader.planner import PlannerOptions, plan_next_cycle

    pile = Pile.trapezoid()
    options = PlannerOptions(force_model=name, max_iter=130, midpoints=True)
    out = plan_next_cycle("gravel", pile, options=options, mpc=False)
    assert out.success and out.check.ok, out.message
    payload = options.force_payload
    cap = 0.2
    if payload is None:
        assert out.check.fill == out.check.carved
        model_end = out.plan.fill[-1]
    else:
        # the heap sees the blade angle as the tip leaves the soil where the payload has a curl term
        exit_angle = 0.0
        if payload.curl_gain != 0.0:
            from wheelloader.estimator import Bucket
            from wheelloader.estimator.payload import exit_angle_profile

            depth = contact_state(out.path.x, out.path.z, out.path.blade_angle, pile, Bucket()).depth
            exit_angle = float(exit_angle_profile(out.path.blade_angle, depth)[-1])
        heaped = max(payload.heap_factor + payload.curl_gain * np.sin(exit_angle), 0.0) * cap
        assert out.check.fill == pytest.approx(float(kept_volume(out.check.carved, cap, payload, 0.0, exit_angle)),
                                               rel=1e-9)
        assert out.check.fill < 0.8 * out.check.carved and out.check.fill <= heaped
        model_end = float(kept_volume(out.plan.fill[-1], cap, payload, 0.0, exit_angle))
    assert out.check.fill == pytest.approx(model_end, rel=0.1)  # the NLP's smooth surface against the pile's
    assert f"predicted fill {out.check.fill / cap:.0%}" in out.message
    if name == "fee-learned":  # inside the correction's trusted depth and speed (the NLP's smooth surface: 1 cm)
        from wheelloader.estimator import Bucket
        from wheelloader.planner.casadi_model import learned_trust

        deepest, fastest = learned_trust(Bucket())
        depth = contact_state(out.path.x, out.path.z, out.path.blade_angle, pile, Bucket()).depth
        assert 0.5 * deepest < depth.max() <= deepest + 0.01
        assert out.check.max_speed <= fastest * 1.01


def test_learned_correction_folded_is_the_network_and_flags_its_range():
    """estimator.learned_plant (the env's form) against LearnedModel.correction on the same inputs."""
    from wheelloader.estimator import Bucket, preset
    from wheelloader.estimator.learned_plant import learned_correction

    bucket, model = Bucket(), default_learned_model()
    for soil in (preset("gravel"), preset("dirt")):
        corr = learned_correction(soil, bucket)
        rng = np.random.default_rng(0)
        cols = [rng.uniform(-0.02, 0.35, 50), rng.uniform(-0.7, 1.4, 50), rng.uniform(-0.1, 0.8, 50),
                rng.uniform(-0.7, 1.0, 50), rng.uniform(0.0, 0.2, 50), rng.uniform(0.0, 0.12, 50),
                rng.uniform(0.0, 1.2, 50)]
        weight = soil.gamma * 9.81 * bucket.floor_length
        soil_inputs = [np.tan(soil.phi), np.tan(soil.delta), soil.cohesion / weight, soil.adhesion / weight]
        x = np.column_stack([*corr.inputs(*cols).T, np.tile(soil_inputs, (50, 1))])
        ref = model.correction(x) * soil.gamma * 9.81 * bucket.width * bucket.floor_length ** 2
        f_t, f_n = corr.rows(*cols)
        np.testing.assert_allclose(f_t, ref[:, 0], rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(f_n, ref[:, 1], rtol=1e-9, atol=1e-6)
        single = np.array([corr.single(*(c[i] for c in cols)) for i in range(50)])
        np.testing.assert_allclose(single, ref, rtol=1e-9, atol=1e-6)
        np.testing.assert_array_equal(corr.outside(*cols), model.outside(x))


def test_removed_volume_inverts_kept_volume():
    from wheelloader.estimator.payload import removed_volume

    for payload in (DEFAULT_PAYLOAD, PayloadOptions(0.7, 0.5, 1.0), PayloadOptions(1.0, 1.0, 50.0)):
        for removed in (0.0, 1e-4, 0.05, 0.1, 0.15):
            kept = float(kept_volume(removed, 0.2, payload))
            assert removed_volume(kept, 0.2, payload) == pytest.approx(removed, rel=1e-9, abs=1e-15)
        assert removed_volume(payload.heap_factor * 0.2, 0.2, payload) == np.inf


def test_mpc_start_fill_is_the_carved_volume_of_the_observed_kept_fill():
    from wheelloader.planner import StartState

    env = BucketLoadingEnv(force_model="fee-payload", sensor_noise=0.0)
    obs, _ = env.reset(seed=0)
    for _ in range(60):
        obs, _, _, _, info = env.step(np.array([0.6, -0.05, 0.0], dtype=np.float32))
    assert 0.0 < info["fill_volume"] < info["carved_volume"]
    start = StartState.from_observation(obs, env.cfg.bucket.capacity, env.cfg.payload)
    assert start.fill == pytest.approx(info["carved_volume"], rel=1e-4)
    assert StartState.from_observation(obs, env.cfg.bucket.capacity).fill == pytest.approx(info["fill_volume"],
                                                                                           rel=1e-4)


def test_fit_payload_recovers_the_env_retention_from_a_logged_fill_or_load():
    from wheelloader.estimator import fit_payload

    truth = PayloadOptions(0.7, 0.6, 3.0)
    logs = [_dig("fee-payload", seed=s, payload=truth)[0].last_cycle_log() for s in (0, 1)]
    start = replace(truth, retention=0.95)
    fitted = fit_payload(logs, free=("retention",), initial=start)
    assert fitted.retention == pytest.approx(0.7, rel=1e-6)
    assert (fitted.heap_factor, fitted.sharpness) == (0.6, 3.0)
    # a log with the load instead of the fill (its soil's density from the metadata, or given)
    gamma = logs[0].metadata["true_soil"]["gamma"]
    loads = [replace(log, fill_volume=None, measured_load=log.fill_volume * gamma * 9.81) for log in logs]
    assert fit_payload(loads, free=("retention",), initial=start).retention == pytest.approx(0.7, rel=1e-6)
    bare = [replace(log, metadata={}) for log in loads]
    from wheelloader.estimator import CalibrationError

    with pytest.raises(CalibrationError, match="density"):
        fit_payload(bare, free=("retention",))
    assert fit_payload(bare, free=("retention",), initial=start, density=gamma).retention == pytest.approx(0.7,
                                                                                                       rel=1e-6)
    with pytest.raises(ParameterError, match="free"):
        fit_payload(logs, free=("retension",))


@pytest.mark.parametrize("name", PAYLOAD_MODELS)
def test_adaptation_loop_calibrates_predicts_and_plans_with_one_model(name):
    """A loop on a plant of the model, calibrating it: the calibration carries the model, the loop's prediction
    uses it, the planner is asked for it, and the record's fill is the kept soil."""
    from wheelloader.adaptation import Calibrating, PlanOutcome, bezier_on_face, hidden_default_soil
    from wheelloader.estimator import Pile, preset
    from wheelloader.loop import run_loop
    from wheelloader.references.fee_env import FEEEnvPlant

    asked = []

    def planner(params, pile, **model):
        asked.append(model)
        return PlanOutcome(bezier_on_face(pile), True, "Bezier", 0.0)

    payload = check_force_model(name, None)
    strategy = Calibrating(preset("sand"), planner=planner, force_model=name)
    records, logs = run_loop(FEEEnvPlant(keep_env=True, force_model=name), strategy, Pile.trapezoid(),
                             hidden_default_soil(), 3, seed=1)
    assert strategy.previous.force_model == name and strategy.previous.payload == payload
    assert asked == [{"force_model": name, "payload": payload}] * 3
    assert records[2].prediction_rmse_percent < 8.0
    assert records[2].fill_fraction == pytest.approx(logs[2].fill_volume[-1] / 0.2)
    assert records[2].fill_fraction <= payload.heap_factor + max(payload.curl_gain, 0.0)  # the curl term's heap


@pytest.mark.parametrize("name", PAYLOAD_MODELS)
def test_cli_calibrate_predict_and_plan_follow_the_calibrations_model(name, tmp_path, capsys):
    """``wheelloader calibrate --force-model`` records the model in params.json; ``predict`` and ``plan`` use it."""
    import json

    from wheelloader.cli import main
    from wheelloader.estimator import CycleLog, calibrate, predict
    from wheelloader.estimator.calibration import CalibrationOptions

    logs = [_dig(name, seed=s)[0].last_cycle_log() for s in (0, 1)]
    for k, log in enumerate(logs):
        log.save(tmp_path / f"log{k}.csv")
    params = tmp_path / "params.json"
    assert main(["calibrate", str(tmp_path / "log0.csv"), "--force-model", name, "-o", str(params)]) == 0
    settings = json.loads(params.read_text())["calibration"]["settings"]
    assert settings["force_model"] == name and settings["payload"] == check_force_model(name, None).to_dict()
    assert main(["predict", str(params), str(tmp_path / "log1.csv"), "-o", str(tmp_path / "forces.csv")]) == 0
    cal = calibrate(CycleLog.load(tmp_path / "log0.csv"), options=CalibrationOptions(force_model=name))
    expected = predict(cal, CycleLog.load(tmp_path / "log1.csv"))
    got = np.genfromtxt(tmp_path / "forces.csv", delimiter=",", names=True)
    np.testing.assert_allclose(got["F_T"], expected.tangential, rtol=1e-6, atol=1e-3)
    assert main(["plan", str(params), "-o", str(tmp_path / "plan.csv")]) == 0
    assert f"force model {name}" in capsys.readouterr().out
    summary = json.loads((tmp_path / "plan.summary.json").read_text())
    assert summary["force_model"] == name
    assert summary["plan"]["fill_m3"] < 0.8 * summary["plan"]["carved_m3"]
    assert main(["calibrate", str(tmp_path / "log0.csv"), "--force-model", "fea", "-o",
                 str(tmp_path / "p2.json")]) == 2
    assert "force_model" in capsys.readouterr().err


@pytest.mark.parametrize("name", PAYLOAD_MODELS)
@pytest.mark.parametrize("backend", ["batched", "serial"])
def test_sb3_adapter_takes_the_model(backend, name):
    pytest.importorskip("stable_baselines3")
    from wheelloader.envs.sb3 import make_sb3_vec_env

    env = make_sb3_vec_env(MAIN_ID, n_envs=2, seed=0, backend=backend, force_model=name)
    env.reset()
    for _ in range(60):
        _, _, _, infos = env.step(np.tile(np.array([[0.6, -0.05, 0.0]], dtype=np.float32), (2, 1)))
    dug = [info for info in infos if info["carved_volume"] > 0.0]
    assert dug and all(info["fill_volume"] < info["carved_volume"] for info in dug)  # the kept soil, not the carving


def test_every_model_runs_in_the_env_and_the_planner():
    from wheelloader.estimator import PlanningError
    from wheelloader.planner import PlannerOptions

    assert PLANT_FORCE_MODELS == FORCE_MODELS and "fee-learned" in FORCE_MODELS
    for name in FORCE_MODELS:
        assert BucketLoadingEnv(force_model=name).cfg.force_model == name
        options = PlannerOptions(force_model=name)
        assert options.force_payload == check_force_model(name, None)
        assert (options.force_payload is not None) == (name in PAYLOAD_MODELS)
    assert PlannerOptions(force_model="fee-learned").kept_payload == default_learned_model().payload
    with pytest.raises(PlanningError, match="force_model"):
        PlannerOptions(force_model="fea")
