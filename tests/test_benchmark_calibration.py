"""The calibration benchmark's committed tables regenerate from its committed JSON byte for byte."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "calibration"


@pytest.mark.skipif(not (RESULTS / "results.json").is_file(), reason="no committed calibration results")
def test_tables_regenerate_from_json(tmp_path):
    for name in ("results.json", "speed.json"):
        if (RESULTS / name).is_file():
            shutil.copy(RESULTS / name, tmp_path / name)
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "calibration.py"), "--from-json", "--out", str(tmp_path)],
                   check=True, capture_output=True)
    for name in ("table.md", "speed.md"):
        if (RESULTS / name).is_file():
            assert (tmp_path / name).read_text() == (RESULTS / name).read_text(), name
