"""``benchmarks/kept_lookahead.py``: the judging of a cycle, the loop figures and the table (synthetic loops), and a
tiny run (slow)."""

from __future__ import annotations

import json
import math

import pytest
from benchmark_scripts import load_benchmark

from wheelloader.estimator import GRAVITY, Bucket
from wheelloader.estimator.force_models import DEFAULT_PAYLOAD
from wheelloader.estimator.payload import kept_volume
from wheelloader.planner.kept import dump_height


def _cycle(bench, fill, energy, z_end, fixed=None):
    row = {"cycle": 1, "path": "planned", "planning_s": 1.0, "between_cycles_s": 1.5, "plan_ok": True,
           "plan_message": "", "prediction_rmse_percent": 20.0, **bench.judge(fill, energy, z_end, 1700.0)}
    if fixed is not None:
        row["fixed_on_pile"] = bench.judge(*fixed, 1700.0)
    return row


def test_judge_known_answer():
    bench = load_benchmark("kept_lookahead")
    row = bench.judge(0.18, 5000.0, 0.9, 1700.0)
    kept = float(kept_volume(0.18, Bucket().capacity, DEFAULT_PAYLOAD))
    assert row["kept_m3"] == pytest.approx(kept)
    assert row["lift_J"] == pytest.approx(1700.0 * GRAVITY * kept * (dump_height() - 0.9))
    assert row["energy_J"] == pytest.approx(5000.0 + row["lift_J"])
    assert bench.judge(0.18, 5000.0, 1.5, 1700.0)["lift_J"] == 0.0


def test_figures_and_report(tmp_path):
    bench = load_benchmark("kept_lookahead")
    cap = Bucket().capacity
    greedy = {"soil": "gravel", "seed": 0, "strategy": "greedy",
              "cycles": [_cycle(bench, 0.18, 5000.0, 1.2, (0.17, 12000.0, 1.2)) for _ in range(6)]}
    look = {"soil": "gravel", "seed": 0, "strategy": "lookahead",
            "cycles": [_cycle(bench, 0.18, 4500.0, 1.2, (0.17, 12000.0, 1.2)) for _ in range(6)]}
    f = bench.loop_figures(greedy)
    kept = float(kept_volume(0.18, cap, DEFAULT_PAYLOAD))
    assert f["kJ_per_kept_m3"] == pytest.approx(5.0 / kept)
    assert f["kept_fill"] == pytest.approx(kept / cap)
    assert f["cycles_to_move"] == math.ceil(bench.MOVE_VOLUME / kept)
    assert f["kept_cycles_ge_fixed"] == 6
    assert f["fixed_kJ_per_kept_m3"] == pytest.approx(12.0 / float(kept_volume(0.17, cap, DEFAULT_PAYLOAD)))
    loops = tmp_path / "loops"
    loops.mkdir()
    for loop in (greedy, look):
        (loops / f"gravel_seed0_{loop['strategy']}_6.json").write_text(json.dumps(loop))
    assert bench.main(["--report", "--out", str(tmp_path), "--soils", "gravel", "--seeds", "1", "--cycles", "6"]) == 0
    text = (tmp_path / "table.md").read_text()
    assert "| lookahead | -10.0 % | -10.0 % | +0 |" in text
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [lp["strategy"] for lp in summary["loops"]] == ["greedy", "lookahead"]


@pytest.mark.slow
def test_quick_run(tmp_path):
    bench = load_benchmark("kept_lookahead")
    assert bench.main(["--quick", "--out", str(tmp_path), "--strategies", "fixed", "kept"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert [lp["strategy"] for lp in summary["loops"]] == ["fixed", "kept"]
    assert all(lp["kept_fill"] > 0.3 for lp in summary["loops"])


def test_lookahead_stats_from_the_messages():
    bench = load_benchmark("kept_lookahead")
    rows = [_cycle(bench, 0.18, 5000.0, 1.2) for _ in range(4)]
    rows[0]["plan_message"] = ("look-ahead chose greedy (greedy 40.0, fill limit 0.80 41.0, energy weight 0.04/kJ "
                               "45.0 kJ/m^3 kept over two cycles; 200 IPOPT it.): IPOPT ...")
    rows[1]["plan_message"] = ("look-ahead chose fill limit 0.80 (greedy 50.0, fill limit 0.80 45.0, energy weight "
                               "0.04/kJ inf kJ/m^3 kept over two cycles; 300 IPOPT it.): IPOPT ...")
    stats = bench.lookahead_stats({"cycles": rows})
    assert stats["non_greedy_choices"] == 1 and stats["cycles_weighed"] == 2
    assert stats["ipopt_iterations_median"] == 250
    assert stats["predicted_gain_percent_median"] == pytest.approx(5.0)
    assert stats["predicted_gain_percent_max"] == pytest.approx(10.0)
    assert stats["next_cycle_error_percent_median"] == pytest.approx(20.0)
