"""``benchmarks/lookahead_mpm_report.py`` (#33: look-ahead against greedy in the MPM plant): known answers on
synthetic rows."""

from __future__ import annotations

import math

import pytest
from benchmark_scripts import load_benchmark


def _row(arm, cycle, fill, lifted, seed=0, soil="gravel", message="IPOPT iterate 60 of 80 (the best)", ok=True):
    return {"arm": arm, "soil": soil, "seed": seed, "cycle": cycle, "fill_m3": fill, "energy_J": lifted,
            "lifted_J": lifted, "capacity_m3": 0.2, "plan_ok": ok, "plan_message": message, "calibration_s": 0.2,
            "planning_s": 1.0 if arm == "greedy" else 6.0, "prediction_rmse_percent": 20.0, "above_limits": False,
            "z_end": 1.2, "iterations": load_benchmark("lookahead_mpm_report").plan_iterations(arm, message)}


CHOSE = ("look-ahead chose fill limit 0.80 (greedy 50.0, fill limit 0.80 45.0, energy weight 0.04 inf kJ/m^3 kept "
         "over two cycles; 420 IPOPT it.): IPOPT Solve_Succeeded in 70 it.")


def test_messages_give_iterations_and_the_predicted_gain():
    report = load_benchmark("lookahead_mpm_report")
    assert report.plan_iterations("greedy", "IPOPT iterate 60 of 80 (the best that passes)") == 80
    assert report.plan_iterations("greedy", "IPOPT Solve_Succeeded in 70 it.; kept 49 %") == 70
    assert report.plan_iterations("lookahead", CHOSE) == 420  # every candidate's, not the chosen plan's 70
    assert math.isnan(report.plan_iterations("greedy", "fell back to the Bezier path"))
    name, gain = report.predicted_gain(CHOSE)
    assert name == "fill limit 0.80" and gain == pytest.approx(10.0)
    assert report.predicted_gain("IPOPT Solve_Succeeded in 70 it.") is None


def test_gain_cycles_to_move_and_verdicts_known_answers():
    report = load_benchmark("lookahead_mpm_report")
    # greedy keeps 0.1 m^3 for 5 kJ each cycle (50 kJ/m^3); the look-ahead 0.12 m^3 for 5.4 kJ (45 kJ/m^3): -10 %
    rows = [_row("greedy", k, 0.10, 5000.0) for k in range(1, 11)]
    rows += [_row("lookahead", 1, 0.10, 5000.0)]  # the same first cycle (it chose greedy's plan there)
    rows += [_row("lookahead", k, 0.12, 5400.0, message=CHOSE) for k in range(2, 11)]
    summary = report.summarise({"rows": rows}, volume=0.8)
    q = summary["loops"]["gravel seed 0"]
    assert q["cycles"] == 10 and q["same_paths_from_cycle1"] == 1
    assert q["greedy"]["kJ_per_kept_m3"] == pytest.approx(50.0)
    la = (5000.0 + 9 * 5400.0) / (0.10 + 9 * 0.12) / 1e3
    assert q["lookahead"]["kJ_per_kept_m3"] == pytest.approx(la)
    assert q["gain_percent"] == pytest.approx(100.0 * (la / 50.0 - 1.0))
    assert q["greedy"]["cycles_to_move"] == 8  # 8 x 0.1
    assert q["lookahead"]["cycles_to_move"] == 7  # 0.1 + 6 x 0.12 = 0.82
    assert q["cycles_to_move_difference"] == -1
    assert q["lookahead"]["non_greedy_choices"] == 9 and q["lookahead"]["iterations_median"] == 420
    assert q["greedy"]["between_total_s_median"] == pytest.approx(1.2)
    assert summary["verdict_gain"] is True  # -9.2 % <= -5 %
    assert summary["verdict_between"] is False  # the look-ahead's 6.2 s
    assert summary["gain_percent_min"] == summary["gain_percent_max"] == summary["gain_percent_median"]
    # spending less by keeping less is judged by energy per m^3 kept: keeping half for 60 % of the energy is worse
    thin = [dict(r, fill_m3=0.05, lifted_J=3000.0) if r["arm"] == "lookahead" and r["cycle"] > 1 else r for r in rows]
    worse = report.summarise({"rows": thin}, volume=0.8)
    assert worse["loops"]["gravel seed 0"]["gain_percent"] > 0 and worse["verdict_gain"] is False
    assert worse["loops"]["gravel seed 0"]["lookahead"]["cycles_to_move"] is None  # 0.55 m^3 in 10 cycles


def test_only_the_cycles_both_arms_dug_are_compared():
    report = load_benchmark("lookahead_mpm_report")
    rows = [_row("greedy", k, 0.10, 5000.0) for k in range(1, 11)]
    rows += [_row("lookahead", k, 0.10, 4000.0) for k in range(1, 4)]  # a run cut short after 3 cycles
    rows += [_row("greedy", k, 0.10, 5000.0, seed=1) for k in range(1, 11)]  # seed 1: no look-ahead yet
    summary = report.summarise({"rows": rows})
    assert list(summary["loops"]) == ["gravel seed 0"]
    assert summary["loops"]["gravel seed 0"]["cycles"] == 3
    assert summary["loops"]["gravel seed 0"]["greedy"]["kJ_per_kept_m3"] == pytest.approx(50.0)
    assert summary["gain_percent_median"] == pytest.approx(-20.0)
    assert report.summarise({"rows": [r for r in rows if r["arm"] == "greedy"]})["loops"] == {}


def test_a_loop_cut_short_is_read_from_its_saved_cycles(tmp_path):
    """Rows from the saved cycles where no JSON was written: greedy's every cycle; the look-ahead's up to the last
    one it planned (its folder started as a copy of greedy's cycles)."""
    import numpy as np

    from wheelloader.estimator import BucketPath, CycleLog, Pile
    from wheelloader.saved_loops import save_cycle

    report = load_benchmark("lookahead_mpm_report")
    t = np.linspace(0.0, 1.0, 6)
    path = BucketPath(t, 0.5 * t, 0.2 * t, 0 * t)

    def save(arm, k, fill, message):
        log = CycleLog(path, np.full(6, 100.0), np.zeros(6), Pile.trapezoid(), fill_volume=np.full(6, fill),
                       metadata={"plan": {"ok": True, "message": message, "seconds": 2.0 * k}})
        save_cycle(tmp_path / arm / "gravel" / "seed0" / "ours", k, log)

    for k in (1, 2, 3):
        save("greedy", k, 0.1, "IPOPT iterate 60 of 80")
    save("lookahead", 1, 0.1, "IPOPT iterate 60 of 80")  # greedy's copy, the same path as the look-ahead's
    save("lookahead", 2, 0.12, CHOSE)  # dug by the look-ahead
    save("lookahead", 3, 0.1, "IPOPT iterate 60 of 80")  # greedy's copy after the look-ahead stopped
    greedy = report.saved_rows(tmp_path / "greedy", "greedy")
    ahead = report.saved_rows(tmp_path / "lookahead", "lookahead")
    assert [r["cycle"] for r in greedy] == [1, 2, 3] and [r["cycle"] for r in ahead] == [1, 2]
    assert ahead[1]["fill_m3"] == 0.12 and ahead[1]["planning_s"] == 4.0 and math.isnan(ahead[1]["calibration_s"])
    assert greedy[0]["energy_J"] == pytest.approx(100.0 * 0.5)  # cycle_work: F_T = 100 N resists +x at 0.5 m/s, 1 s
    rows = [dict(r, arm="greedy", lifted_J=r["energy_J"], capacity_m3=0.2, iterations=80.0) for r in greedy]
    rows += [dict(r, arm="lookahead", lifted_J=r["energy_J"], capacity_m3=0.2, iterations=80.0) for r in ahead]
    summary = report.summarise({"rows": rows})
    assert summary["loops"]["gravel seed 0"]["cycles"] == 2
    assert math.isnan(summary["loops"]["gravel seed 0"]["lookahead"]["between_total_s_median"])
