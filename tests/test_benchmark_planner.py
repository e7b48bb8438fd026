"""Smoke test of ``benchmarks/planner.py``: a tiny configuration through its ``main(argv)``.

The full benchmark (five soils, five repeats) takes minutes and is marked ``slow``.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from benchmark_scripts import load_benchmark


def _check_results(out: Path, soils: list[str]) -> dict:
    results = json.loads((out / "results.json").read_text())
    assert results["benchmark"] == "planner"
    assert "casadi" in results["machine"]["versions"]
    assert list(results["soils"]) == soils
    for soil in soils:
        strategies = results["soils"][soil]["strategies"]
        assert {"plan (true soil)", "plan (nominal)", "MPC (true soil)", "MPC from plan"} <= set(strategies)
        for row in strategies.values():
            for view in ("numpy", "env"):
                assert 0.0 <= row[view]["fill_fraction"] <= 1.0 + 1e-9
                assert row[view]["energy"] >= 0.0
        for variant in ("MPC (true soil)", "MPC from plan", "MPC (true soil), IPOPT", "MPC from plan, IPOPT"):
            mpc = strategies[variant]["mpc"]
            assert mpc["solves"] == len(mpc["history"]) >= 1
            assert all(r["seconds"] > 0.0 and r["cpu_seconds"] >= 0.0 for r in mpc["history"])
            assert mpc["solver"] == ("ipopt" if variant.endswith("IPOPT") else "sqp")
        for variant, versus in results["soils"][soil]["mpc_vs_ipopt"].items():
            assert versus["against"] == variant + ", IPOPT" and versus["energy_per_m3_ratio"]["env"] > 0.0
        timing = results["soils"][soil]["timing"]
        assert timing["cold"]["count"] >= 1 and timing["warm"]["count"] >= 2
    targets = results["targets"]
    for key in ("mpc_warm_solve_median_met", "full_plan_cold_median_met", "full_plan_warm_median_met",
                "mpc_warm_replan_cpu_median_met", "mpc_warm_replan_wall_median_met"):
        assert targets[key] in (True, False, None)
    assert results["solver_variants"]["fatrop"]["status"] in ("refused", "built", "no fatrop plugin in this CasADi")
    assert results["timing"]["full_plan_cold"]["median"] > 0.0
    return results


def test_planner_benchmark_smoke(tmp_path):
    """One soil, one repeat, two fixed paths, an MPC re-plan once a second: JSON and PNGs written."""
    bench = load_benchmark("planner")
    out = tmp_path / "planner"
    rc = bench.main(["--out", str(out), "--soils", "sand", "--repeats", "1", "--paths", "1", "2",
                     "--replan-every", "60", "--no-compiled"])
    assert rc == 0
    _check_results(out, ["sand"])
    for name in ("planner_energy.png", "planner_timing.png", "planner_summary.png"):
        assert (out / name).stat().st_size > 1000


@pytest.mark.slow
def test_planner_benchmark_quick(tmp_path):
    bench = load_benchmark("planner")
    out = tmp_path / "planner"
    assert bench.main(["--quick", "--out", str(out), "--no-compiled"]) == 0
    results = _check_results(out, ["gravel", "sand", "dirt"])
    assert (out / "planner_summary.png").exists()
    assert results["repeats"] == 2
