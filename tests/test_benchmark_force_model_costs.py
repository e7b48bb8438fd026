"""Smoke test of ``benchmarks/force_model_costs.py``: a tiny configuration through its ``main(argv)``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from wheelloader.estimator import FORCE_MODELS

BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "force_model_costs.py"


def test_force_model_costs_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_force_model_costs", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(["--quick", "--steps", "300", "--rounds", "1", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "results.json").read_text())
    assert list(results["models"]) == list(FORCE_MODELS)
    fee = results["models"]["fee"]
    assert fee["env_step_ratio"] == 1.0 and fee["plan_cold_ratio"] == 1.0
    for m in results["models"].values():
        assert m["env_step_cpu_us"] > 0.0 and m["plans"] == 1 and m["plan_rows"][0]["soil"] == "gravel"
        assert 0.0 < m["fill_median"] <= m["carved_median"] + 1e-12
    table = (tmp_path / "table.md").read_text()
    assert all(f"| {name} |" in table for name in FORCE_MODELS)
