"""Inputs are never written: not by name, not through a symlink or a hard link, not inside a directory a
command reads, not in the shipped data; an output in use by another run is refused naming it (#29).

The shipped data set is never the test subject: every case works on a copy in ``tmp_path``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wheelloader.cli import main
from wheelloader.cli.staging import LOCK_SUFFIX, OutputRun, shipped_data_dir
from wheelloader.estimator import ParameterError, paper_paths, preset, save_path_csv, synthetic_cycle

REFERENCE = Path(__file__).resolve().parents[1] / "data" / "reference"


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _error(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("wheelloader: error: "), err
    return lines[0]


@pytest.fixture()
def reference_copy(tmp_path):
    """A copy of the shipped DEM reference set (3 MB), so that the old code's overwrite hits the copy."""
    copy = tmp_path / "reference"
    shutil.copytree(REFERENCE, copy)
    return copy


@pytest.fixture()
def inputs(tmp_path):
    synthetic_cycle("gravel", noise=0.0).save(tmp_path / "log.csv")
    save_path_csv(paper_paths()[1], tmp_path / "path.csv")
    (tmp_path / "params.json").write_text(json.dumps({"soil": preset("gravel").to_dict()}))
    return tmp_path


@pytest.mark.parametrize("name", ["gravel_path1.csv", "gravel_path1.json", "sub.json"])
def test_dem_sanity_never_writes_into_the_data_it_reads(reference_copy, capsys, name):
    before = _snapshot(reference_copy)
    code = main(["dem", "sanity", "--data", str(reference_copy), "--json", str(reference_copy / name), "--force"])
    assert code == 2
    assert "input" in _error(capsys)
    assert _snapshot(reference_copy) == before


def test_an_output_reaching_an_input_through_a_symlink_or_hard_link_is_refused(inputs, capsys):
    os.symlink(inputs / "params.json", inputs / "alias.json")
    os.link(inputs / "path.csv", inputs / "twin.csv")
    before = _snapshot(inputs)
    assert main(["calibrate", str(inputs / "log.csv"), "--initial", str(inputs / "params.json"), "-o",
                 str(inputs / "alias.json"), "--force"]) == 2
    assert "input files" in _error(capsys)
    assert main(["predict", "gravel", str(inputs / "path.csv"), "-o", str(inputs / "twin.csv"), "--force"]) == 2
    assert "input files" in _error(capsys)
    assert _snapshot(inputs) == before


def test_nothing_is_written_into_the_shipped_data(inputs, capsys):
    data = shipped_data_dir()
    if data is None:
        pytest.skip("not a source checkout")
    target = data / "reference" / f"never-written-{os.getpid()}.csv"
    try:
        assert main(["predict", "gravel", str(inputs / "path.csv"), "-o", str(target)]) == 2
        assert "shipped data" in _error(capsys)
        assert not target.exists()
    finally:
        target.unlink(missing_ok=True)


def test_an_output_directory_holding_an_input_is_refused(inputs, capsys):
    out = OutputRun(inputs=[inputs / "log.csv"], force=True)
    with pytest.raises(ParameterError, match="holds the input"):
        out.directory("-o/--out", inputs, fresh=False)


def test_a_fifo_input_is_refused_without_blocking(inputs):
    fifo = inputs / "fifo.csv"
    os.mkfifo(fifo)
    shutil.copy(inputs / "log.json", inputs / "fifo.json")
    proc = subprocess.run([sys.executable, "-m", "wheelloader.cli", "calibrate", str(fifo), "-o",
                           str(inputs / "p.json")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "not a regular file" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "wheelloader.cli", "predict", "gravel", str(fifo), "-o",
                           str(inputs / "f.csv")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "not a regular file" in proc.stderr, proc.stderr


HOLDER = """
import sys, time
from wheelloader.cli.staging import _Lock
from pathlib import Path
_Lock(Path(sys.argv[1]), "wheelloader calibrate (the first run)").acquire(None)
print("locked", flush=True)
time.sleep(120)
"""


def test_a_second_run_on_the_same_output_is_refused_naming_the_first_and_a_dead_lock_is_taken_over(inputs, capsys):
    out = inputs / "params-out.json"
    holder = subprocess.Popen([sys.executable, "-c", HOLDER, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        code = main(["calibrate", str(inputs / "log.csv"), "-o", str(out)])
        line = _error(capsys)
        assert code == 2
        assert f"PID {holder.pid}" in line and "the first run" in line and "in use" in line
        assert not out.exists()
    finally:
        holder.kill()  # dies without releasing: its lock file stays, naming a dead PID
        holder.wait()
    lock = out.with_name(f".{out.name}{LOCK_SUFFIX}")
    assert json.loads(lock.read_text())["pid"] == holder.pid
    assert main(["calibrate", str(inputs / "log.csv"), "-o", str(out)]) == 0
    assert out.is_file() and not lock.exists()


@pytest.mark.slow  # the lock itself is tested above in a second; this runs two real plans
def test_two_concurrent_runs_of_a_real_command(inputs, tmp_path):
    """Two ``plan`` runs into the same output at once: the second is refused naming the first, which
    completes."""
    argv = [sys.executable, "-m", "wheelloader.cli", "plan", str(inputs / "params.json"), "-o", str(tmp_path / "p.csv")]
    first = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lock = tmp_path / f".p.csv{LOCK_SUFFIX}"
    deadline = time.monotonic() + 120
    while not lock.exists() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    second = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    out, err = first.communicate(timeout=600)
    assert first.returncode in (0, 1), err
    assert second.returncode == 2, second.stderr
    assert f"PID {first.pid}" in second.stderr and "in use" in second.stderr
    assert (tmp_path / "p.csv").is_file()
