"""``.ci/run``: the default suite, then the slow tests as a second step whose "no tests collected" passes."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script() -> str:
    return (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def _slow_step() -> str:
    text = _script()
    start = text.index("status=0")
    return text[start: text.index("\nfi", start) + 3]


def test_the_slow_tests_run_after_the_default_suite():
    text = _script()
    default, slow = text.index("pytest -q -n 2\n"), text.index("pytest -q -n 2 -m slow")
    assert default < slow


@pytest.mark.parametrize(("status", "expected"), [(0, 0), (5, 0), (1, 1), (2, 2)])
def test_the_slow_step_fails_on_failures_not_on_no_tests(tmp_path, status, expected):
    """pytest's exit status 5 (no tests collected) passes; a failure (1) or an error (2) fails the run."""
    fake = tmp_path / "pytest"
    fake.write_text(f'#!/bin/sh\necho "$@" > "{tmp_path}/args"\nexit {status}\n', encoding="utf-8")
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{tmp_path}{os.pathsep}{os.environ.get('PATH', '')}"}
    proc = subprocess.run(["bash", "-c", "set -euo pipefail\n" + _slow_step() + "\necho step-done\n"],
                          env=env, capture_output=True, text=True)
    assert proc.returncode == expected, proc.stderr
    assert ("step-done" in proc.stdout) is (expected == 0)
    assert "-m slow" in (tmp_path / "args").read_text(encoding="utf-8")
