"""``benchmarks/fee_learned.py``: the network it trains (seeded, exact gradient) and the split it ships."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

from wheelloader.estimator.learned import INPUT_NAMES, contact_gate, default_learned_model

ROOT = Path(__file__).resolve().parents[1]


def test_training_is_seeded_and_learns_a_known_function():
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(1)
    x = rng.uniform(-1.0, 1.0, (400, len(INPUT_NAMES)))
    x[:, 1] = rng.uniform(0.05, 2.0, len(x))  # the contact ramp: the gate is below 1 under 1
    r = contact_gate(x[:, 1])[:, None] * np.column_stack([np.tanh(x[:, 0] - 0.5 * x[:, 8]), 0.3 * x[:, 2]])
    w = np.full(len(x), 1.0 / len(x))
    a = fl.train_mlp(x, r, w, hidden=6, l2=1e-6, max_iter=400)
    b = fl.train_mlp(x, r, w, hidden=6, l2=1e-6, max_iter=400)
    np.testing.assert_array_equal(a.w1, b.w1)
    assert min(fl.r2(a.correction(x), r)) > 0.95


def test_a_form_without_the_soil_inputs_ignores_them():
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(2)
    x = rng.uniform(-1.0, 1.0, (200, len(INPUT_NAMES)))
    r = np.column_stack([x[:, 0], x[:, 9]])
    mask = np.ones(len(INPUT_NAMES))
    mask[8:] = 0.0
    m = fl.train_mlp(x, r, np.full(len(x), 1 / len(x)), hidden=4, max_iter=200, mask=mask)
    moved = x.copy()
    moved[:, 8:] += 0.3
    np.testing.assert_allclose(m.correction(moved), m.correction(x), atol=1e-12)


def test_the_shipped_weights_name_their_build_and_split():
    manifest = default_learned_model().manifest
    fl = load_benchmark("fee_learned")
    assert manifest["command"] == fl.COMMAND
    split = manifest["split"]
    assert set(split["test"]) == {"gravel", "sand", "modified_sand", "dirt", "gravel_slope25"}
    trained = {f for files in split["train"].values() for f in files}
    assert not trained & {f for files in split["validation"].values() for f in files}


def test_a_missing_folder_is_one_line_exit_2(tmp_path, capsys):
    assert load_benchmark("fee_learned").main(["--out", str(tmp_path), "--data", str(tmp_path / "none")]) == 2
    assert capsys.readouterr().err.startswith("wheelloader: error:")


@pytest.mark.parametrize("count", [1, 3])
def test_r2_of_a_perfect_prediction_is_one(count):
    r = np.arange(2.0 * 5 * count).reshape(-1, 2) ** 1.5
    assert load_benchmark("fee_learned").r2(r, r) == [1.0, 1.0]


def test_the_mean_network_is_the_mean_of_its_members():
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(3)
    x = rng.uniform(-1.0, 1.0, (150, len(INPUT_NAMES)))
    x[:, 1] = rng.uniform(0.0, 1.5, len(x))
    r = np.column_stack([x[:, 0] ** 2, x[:, 3]])
    w = np.full(len(x), 1.0 / len(x))
    members = [fl.train_mlp(x, r, w, hidden=3, max_iter=50, seed=s) for s in range(3)]
    mean = fl.mean_network(members)
    assert mean.hidden == 9
    np.testing.assert_allclose(mean.correction(x), np.mean([m.correction(x) for m in members], axis=0),
                               rtol=1e-12, atol=1e-12)


def test_the_loop_cycles_weigh_their_share():
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(4)

    def group(n):
        x = rng.uniform(0.1, 1.0, (n, len(INPUT_NAMES)))
        return {"blocks": [{"own": (x, x[:, :2], x[:, :2]), "cross": [(x, x[:, :2], x[:, :2])]}]}

    learn, loops = [group(30)], [group(70)]
    x, _, w = fl.stack(learn, loops=loops, loop_share=0.2)
    assert len(x) == 200 and w.sum() == pytest.approx(1.0)
    assert w[60:].sum() == pytest.approx(0.2)
    assert len(fl.stack(learn, loops=loops, loop_share=0.0)[0]) == 60


def test_the_shipped_weights_keep_the_payload_the_transfer_benchmark_chooses():
    # fee-learned's kept fill is the validated one: its payload is transfer.py's choice (docs/results/transfer)
    import json

    from wheelloader.estimator.payload import PayloadOptions

    manifest = default_learned_model().manifest
    chosen = json.loads((ROOT / "docs" / "results" / "transfer" / "transfer.json").read_text())["payload"]
    assert default_learned_model().payload == PayloadOptions.from_dict(chosen)
    assert manifest["payload_source"]["recipe"]["cycles"] == "train + extra"


def _net(rng, h=5):
    return rng.normal(size=(len(INPUT_NAMES), h)), rng.normal(size=h), rng.normal(size=(h, 2))


@pytest.mark.parametrize(("slope", "curvature"), [(1.0, 0.0), (0.0, 1.0), (0.7, 0.3)])
def test_the_smoothness_penalty_is_the_jacobian_and_hessian_norm_with_its_exact_gradient(slope, curvature):
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(5)
    z = rng.normal(size=(40, len(INPUT_NAMES)))
    pw = rng.uniform(size=40)
    pw /= pw.sum()
    w1, b1, w2 = _net(rng)
    rows = np.array([0.0 if n in fl.SOIL_INPUTS else 1.0 for n in INPUT_NAMES])
    value, grads = fl.smoothness_penalty(z, pw, w1, b1, w2, rows, slope, curvature)
    a = np.tanh(z @ w1 + b1)
    s, t = 1.0 - a * a, -2.0 * a * (1.0 - a * a)
    p = rows > 0
    jac = np.einsum("jh,nh,hk->njk", w1[p], s, w2)
    hess = np.einsum("jh,lh,nh,hk->njlk", w1[p], w1[p], t, w2)
    brute = slope * np.sum(pw * np.sum(jac ** 2, axis=(1, 2))) + curvature * np.sum(pw * np.sum(hess ** 2,
                                                                                                    axis=(1, 2, 3)))
    assert value == pytest.approx(brute, rel=1e-12)
    for k, arr in enumerate((w1, b1, w2)):
        numeric = np.zeros_like(arr)
        for i in np.ndindex(arr.shape):
            old = arr[i]
            arr[i] = old + 1e-6
            up = fl.smoothness_penalty(z, pw, w1, b1, w2, rows, slope, curvature)[0]
            arr[i] = old - 1e-6
            down = fl.smoothness_penalty(z, pw, w1, b1, w2, rows, slope, curvature)[0]
            arr[i] = old
            numeric[i] = (up - down) / 2e-6
        np.testing.assert_allclose(grads[k], numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


def test_the_penalised_training_has_an_exact_gradient(monkeypatch):
    import scipy.optimize

    fl = load_benchmark("fee_learned")
    captured = {}
    real = scipy.optimize.minimize

    def once(fun, x0, **kwargs):
        captured["fun"], captured["x0"] = fun, x0
        return real(fun, x0, **{**kwargs, "options": {"maxiter": 1}})

    monkeypatch.setattr(scipy.optimize, "minimize", once)
    rng = np.random.default_rng(6)
    x = rng.uniform(-1.0, 1.0, (60, len(INPUT_NAMES)))
    x[:, 1] = rng.uniform(0.05, 2.0, len(x))
    mask = np.ones(len(INPUT_NAMES))
    mask[INPUT_NAMES.index("kept_fill_fraction")] = 0.0
    fl.train_mlp(x, rng.normal(size=(60, 2)), np.full(60, 1 / 60), hidden=3, l2=1e-3, mask=mask, slope=0.3,
                 curvature=0.2, box=0.5)
    fun = captured["fun"]
    theta = captured["x0"] + rng.normal(0.0, 0.3, captured["x0"].shape)
    grad = fun(theta)[1]
    numeric = np.array([(fun(theta + e)[0] - fun(theta - e)[0]) / 2e-6 for e in np.eye(len(theta)) * 1e-6])
    np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-7 * np.abs(numeric).max())


def test_the_smoothness_and_box_penalties_flatten_the_network_where_the_planner_moves():
    fl = load_benchmark("fee_learned")
    rng = np.random.default_rng(7)
    x = rng.uniform(-1.0, 1.0, (300, len(INPUT_NAMES)))
    x[:, 1] = 1.0
    r = np.column_stack([np.sin(4.0 * x[:, 0]), np.cos(3.0 * x[:, 2])]) + 0.1 * rng.normal(size=(300, 2))
    w = np.full(len(x), 1.0 / len(x))
    rows = np.array([0.0 if n in fl.SOIL_INPUTS else 1.0 for n in INPUT_NAMES])

    def steepness(m):
        z = (np.clip(x, m.low, m.high) - m.mean) / m.std
        return fl.smoothness_penalty(z, w, m.w1, m.b1, m.w2, rows, 1.0, 0.0)[0]

    free = fl.train_mlp(x, r, w, hidden=6, l2=1e-4, max_iter=200)
    smooth = fl.train_mlp(x, r, w, hidden=6, l2=1e-4, max_iter=200, slope=1.0)
    boxed = fl.train_mlp(x, r, w, hidden=6, l2=1e-4, max_iter=200, box=10.0)
    assert steepness(smooth) < 0.5 * steepness(free)
    assert np.mean(boxed.ungated(x) ** 2) < np.mean(free.ungated(x) ** 2)


def test_the_planner_gate():
    fl = load_benchmark("fee_learned")
    fee = {"iterations_median": 70.0}

    def plans(iterations, status="Solve_Succeeded", ok=True):
        return {"iterations_median": float(iterations), "plans": [{"status": status, "check_ok": ok}] * 3}

    form = fl.Form(8, 1e-3, 0.2)
    assert fl.plannable(form, plans(70), fee)
    assert not fl.plannable(form, plans(71), fee)
    assert not fl.plannable(form, plans(50, status="Maximum_Iterations_Exceeded"), fee)
    assert not fl.plannable(form, plans(50, ok=False), fee)
    assert not fl.plannable(form._replace(drop=()), plans(50), fee)


def test_cold_plans_use_the_given_network_and_leave_the_shipped_one_in_place():
    import os

    import wheelloader.estimator.learned as learned_module

    fl = load_benchmark("fee_learned")
    shipped = default_learned_model()
    cache = os.environ.get("WHEELLOADER_NLP_CACHE")
    calls = []
    model = shipped

    class Spy:
        def __getattr__(self, name):
            calls.append(name)
            return getattr(model, name)

    out = fl.cold_plans("fee-learned", Spy(), soils=("gravel",))
    assert calls and out["plans"][0]["iterations"] > 0
    assert learned_module.default_learned_model() is shipped
    assert os.environ.get("WHEELLOADER_NLP_CACHE") == cache


def test_the_forms_table_has_a_row_per_form_and_no_test_rows():
    fl = load_benchmark("fee_learned")
    plan = {"iterations": 60, "status": "Solve_Succeeded", "check_ok": True, "cpu_s": 0.5}
    planner = {"iterations_median": 60.0, "cpu_median_s": 0.5, "plans": [plan] * 3}
    report = {"fee_cold_plans": {"iterations_median": 70.0, "cpu_median_s": 0.4, "plans": [plan] * 3},
              "chosen": "a",
              "forms": {"base": {"validation": {"one_cycle": 28.4, "floor": 12.6}},
                        "a": {"validation": {"one_cycle": 26.0, "floor": 12.0}, "planner": planner, "plannable": True,
                              "r2_tangential_normal_transfer": {"train": [0.3, 0.6], "validation": [0.0, 0.1],
                                                                "gravel": [0.9, 0.9]}}}}
    table = fl.forms_table(report)
    assert len(table.splitlines()) == 5
    assert "| a | 26.0 / 12.0 % | 0.30 / 0.60 | 0.00 / 0.10 | 60, 60, 60; 60 | 1.25x | passes | yes |" in table
    assert "0.90" not in table


def test_a_form_s_network_carries_the_build_s_payload():
    from wheelloader.estimator.payload import PayloadOptions

    fl = load_benchmark("fee_learned")
    shipped = default_learned_model()
    bare = type(shipped)(shipped.w1, shipped.b1, shipped.w2, shipped.b2, shipped.mean, shipped.std, shipped.low,
                         shipped.high)
    assert bare.payload != shipped.payload  # a bare network keeps the default payload
    carried = fl.with_payload(bare, shipped.payload)
    assert carried.payload == shipped.payload and isinstance(carried.payload, PayloadOptions)
    np.testing.assert_array_equal(carried.w1, shipped.w1)
