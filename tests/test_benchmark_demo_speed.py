"""The demo speed benchmark: its committed table regenerates from its committed JSON; it needs a baseline."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "demo_speed.py"
RESULTS = ROOT / "docs" / "results" / "demo_speed"


@pytest.mark.skipif(not (RESULTS / "speed.json").is_file(), reason="no committed demo speed results")
def test_table_regenerates_from_json(tmp_path):
    shutil.copy(RESULTS / "speed.json", tmp_path / "speed.json")
    subprocess.run([sys.executable, str(SCRIPT), "--from-json", "--out", str(tmp_path)], check=True,
                   capture_output=True)
    assert (tmp_path / "table.md").read_text() == (RESULTS / "table.md").read_text()
    assert (tmp_path / "speed.png").stat().st_size > 0


def test_a_run_needs_a_baseline(tmp_path):
    done = subprocess.run([sys.executable, str(SCRIPT), "--out", str(tmp_path)], capture_output=True, text=True)
    assert done.returncode == 2 and "--baseline REV is required" in done.stderr
    assert not (tmp_path / "speed.json").exists()
