"""benchmarks/env_speed_load.py: one row per block length, positive rates, ratios from the rates."""


import pytest
from benchmark_scripts import load_benchmark


def test_rows_per_block_with_rates_and_their_ratio():
    rows = load_benchmark("env_speed_load").measure(steps=40, tries=2, blocks=[40, 10])
    assert [r["block"] for r in rows] == [40, 10]
    for r in rows:
        assert r["steps_per_s"] > 0.0 and r["cartpole_steps_per_s"] > 0.0
        assert r["ratio_best"] == pytest.approx(r["steps_per_s"] / r["cartpole_steps_per_s"])
        assert r["ratio_median"] > 0.0
