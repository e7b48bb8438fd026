"""The installed package imports from anywhere and the console script works."""

import json
import subprocess
import sys

import pytest


def test_import_from_another_directory(tmp_path):
    code = "import wheelloader.estimator, wheelloader.envs, wheelloader.planner; print(wheelloader.__version__)"
    result = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, check=True)
    assert result.stdout.strip()


def test_cli_help_and_unknown_command():
    from wheelloader.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code == 2


def test_demo_writes_figure_and_summary_without_overwriting(tmp_path, capsys):
    from wheelloader.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--cycles", "2", "--seeds", "1"]) == 0
    assert (out / "summary.json").exists()
    summary = json.loads((out / "summary.json").read_text())
    for name in summary["figures"]:
        assert (out / name).stat().st_size > 1000
    # a second run must not overwrite the first
    assert main(["demo", "--out", str(out), "--cycles", "1", "--no-planner", "--seeds", "2"]) == 0
    assert (tmp_path / "demo-2" / "summary.json").exists()
    assert str(tmp_path / "demo-2") in capsys.readouterr().out


def test_demo_rejects_a_bad_cycle_count(tmp_path, capsys):
    from wheelloader.cli import main

    assert main(["demo", "--out", str(tmp_path / "d"), "--cycles", "0"]) == 2
    assert "--cycles" in capsys.readouterr().err
