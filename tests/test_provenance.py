"""``wheelloader.provenance.package_at_revision``: the baseline package the speed benchmarks run beside today's."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from wheelloader.provenance import package_at_revision


def test_package_at_revision_is_that_commit_laid_out_as_the_package(tmp_path):
    root = Path(__file__).resolve().parents[1]
    if not (root / ".git").exists():
        pytest.skip("not a git checkout")
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                          check=True).stdout.strip()
    commit, pkg = package_at_revision(root, "HEAD", tmp_path / "base")
    assert commit == head
    shipped = subprocess.run(["git", "-C", str(root), "show", f"{head}:estimator/pile.py"], capture_output=True,
                             check=True).stdout
    assert (pkg / "wheelloader" / "estimator" / "pile.py").read_bytes() == shipped
    for sub in ("estimator", "envs", "planner"):
        assert (pkg / "wheelloader" / sub / "__init__.py").is_file()
    assert (pkg / "wheelloader" / "cli").is_dir()
