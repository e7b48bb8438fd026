"""benchmarks/mpm_speed.py on the tiny scene: old and new kernels side by side, the report's fields (slow: two
Taichi processes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_mpm_speed_benchmark_on_the_tiny_scene(tmp_path, monkeypatch):
    pytest.importorskip("taichi")
    monkeypatch.setenv("WHEELLOADER_MPM_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "speed"
    cmd = [sys.executable, str(ROOT / "benchmarks" / "mpm_speed.py"), "--out", str(out), "--cycles", "tiny",
           "--variants", "old", "new-1t", "new-2t", "new-2t-cached"]
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=1800)
    summary = json.loads((out / "mpm_speed.json").read_text())
    rows = summary["results"]["cycles"]["tiny"]
    assert set(rows) >= {"old", "new-1t", "new-2t", "new-2t-cached", "cache_hit_bit_identical"}
    assert rows["cache_hit_bit_identical"] is True
    assert rows["new-2t"]["settle_cache"] == "miss" and rows["new-2t-cached"]["settle_cache"] == "hit"
    for name in ("new-1t", "new-2t"):
        assert 0.0 < rows[name]["filtered_fr_vs_old_percent"] < 1.0
        assert rows[name]["cpu_s"] > 0.0 and rows[name]["wall_s"] > 0.0
    assert rows["old"]["filtered_fr_vs_old_percent"] == 0.0
    assert (out / "mpm_speed.png").stat().st_size > 0
    # nothing of the settle cache was written into the output
    assert not list(out.rglob("*.npz"))


def test_members_name_their_variant_and_perturbation():
    mod = load_benchmark("mpm_speed")
    assert mod.split_variant("old") == ("old", {})
    assert mod.split_variant("old~order2") == ("old", {"order_seed": 2})
    assert mod.split_variant("new-1t-svdF~ulp13") == ("new-1t-svdF", {"ulp_seed": 13})
    for bad in ("older", "old~order", "old~shuffle1"):
        with pytest.raises(ValueError):
            mod.split_variant(bad)


def test_envelope_puts_a_run_like_the_old_members_inside_and_a_biased_one_outside():
    mod = load_benchmark("mpm_speed")
    t = np.arange(0.0, 3.0, 1.0 / 60.0)
    rng = np.random.default_rng(0)
    shape = 1000.0 * np.sin(np.pi * t / 3.0) ** 2 + 100.0

    def run(scale: float, noise: float) -> dict:
        tangential = shape * scale + noise * rng.standard_normal(t.size).cumsum()
        return {"t": t.tolist(), "tangential": tangential.tolist(), "normal": np.zeros_like(t).tolist(),
                "fill_end": 0.1}

    runs = {"old": run(1.0, 2.0), "old~order1": run(1.0, 2.0), "old~order2": run(1.0, 2.0),
            "new-1t": run(1.0, 2.0), "new-1t~order1": run(1.1, 2.0)}
    env = mod.envelope(runs)
    assert env["old_members"] == ["old", "old~order1", "old~order2"]
    assert env["runs"]["old"]["vs_old"] == 0.0
    assert 0.0 < env["old_spread"]["whole"]["min"] <= env["old_spread"]["whole"]["max"]
    assert env["runs"]["new-1t"]["inside"] and not env["runs"]["new-1t~order1"]["inside"]
    assert env["runs"]["new-1t~order1"]["vs_old"] > 5.0  # about the 10 % bias
    assert env["groups"]["new-1t"]["members"] == ["new-1t", "new-1t~order1"]
    lines = "\n".join(mod.envelope_table("case", env))
    assert "**no**" in lines and "new-1t~order1" in lines


def test_tolerance_holds_the_plant_kernels_and_the_at_rest_wall_of_the_svd_diagnostic():
    mod = load_benchmark("mpm_speed")
    env = {"runs": {"old": {"variant": "old", "inside": True, "inside_early": True},
                    "new-1t": {"variant": "new-1t", "inside": True, "inside_early": True},
                    "new-1t~order1": {"variant": "new-1t", "inside": False, "inside_early": True},
                    "new-1t-svdF": {"variant": "new-1t-svdF", "inside": False, "inside_early": False}}}
    verification = {"wall": {"old": {"percent_vs_old": {"at_rest": 0.0, "passive": 0.0}},
                             "new-2t": {"percent_vs_old": {"at_rest": -6.5, "passive": -0.6}},
                             "new-1t-svdF": {"percent_vs_old": {"at_rest": -0.7, "passive": -0.3}}}}
    check = mod.tolerance({"reproducibility": {"case": env}, "verification": verification})
    assert check["cycles"]["case"] == {"runs": 2, "inside": 1, "inside_early": 2, "met": False, "met_early": True}
    assert set(check["verification"]) == {"wall passive (new-2t)", "wall at_rest (new-1t-svdF)"}
    assert all(v["met"] for v in check["verification"].values())
    assert check["met"] is False
    env["runs"]["new-1t~order1"]["inside"] = True
    assert mod.tolerance({"reproducibility": {"case": env}, "verification": verification})["met"] is True
    verification["wall"]["new-2t"]["percent_vs_old"]["passive"] = 1.5
    assert mod.tolerance({"reproducibility": {"case": env}, "verification": verification})["met"] is False
