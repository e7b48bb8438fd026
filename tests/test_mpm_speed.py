"""benchmarks/mpm_speed.py on the tiny scene: old and new kernels side by side, the report's fields (slow: two
Taichi processes)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

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
