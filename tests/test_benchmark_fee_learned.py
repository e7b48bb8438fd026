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
