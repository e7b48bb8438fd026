"""Every command's outputs: checked before work, written atomically, never over an input, clear errors.

The audit's output classes (#13): output = input, output = plot, an existing file without --force, a
full disk (/dev/full and ENOSPC in the middle of a write), a read-only directory, a directory or a file
where a directory is expected. Each gives exit status 2, one ``wheelloader: error:`` line, no traceback,
and leaves every file the user had as it was, with no half-written file behind.
"""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest

from wheelloader.cli import main
from wheelloader.cli.output import atomic_output, check_outputs, write_json
from wheelloader.estimator import ParameterError, paper_paths, preset, save_path_csv, synthetic_cycle


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    synthetic_cycle("gravel", noise=0.0).save(d / "log.csv")
    save_path_csv(paper_paths()[1], d / "path.csv")
    (d / "params.json").write_text(json.dumps({"soil": preset("gravel").to_dict()}))
    return d


def _snapshot(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("wheelloader: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _copy_inputs(files: Path, tmp_path: Path) -> None:
    for p in files.iterdir():
        (tmp_path / p.name).write_bytes(p.read_bytes())


@pytest.mark.parametrize("argv, message", [
    (["calibrate", "{d}/log.csv", "-o", "{d}/r.png", "--plot", "{d}/r.png"], "given twice"),
    (["calibrate", "{d}/log.csv", "-o", "{d}/log.json", "--force"], "input files"),
    (["calibrate", "{d}/log.csv", "-o", "{d}/log.csv", "--force"], "input files"),
    (["predict", "gravel", "{d}/log.csv", "-o", "{d}/log.csv", "--force"], "input files"),
    (["predict", "gravel", "{d}/path.csv", "-o", "{d}/path.csv", "--force"], "input files"),
    (["predict", "{d}/params.json", "{d}/path.csv", "-o", "{d}/params.json", "--force"], "input files"),
    (["predict", "gravel", "{d}/path.csv", "-o", "{d}/f.png", "--plot", "{d}/f.png", "--force"], "given twice"),
    (["plan", "{d}/params.json", "-o", "{d}/params.csv", "--plot", "{d}/params.csv"], "given twice"),
    (["calibrate", "{d}/log.csv", "-o", "/dev/full"], "not a regular file"),
    (["predict", "gravel", "{d}/path.csv", "-o", "/dev/full", "--force"], "not a regular file"),
    (["calibrate", "{d}/log.csv", "-o", "{d}"], "is a directory"),
    (["calibrate", "{d}/log.csv", "-o", "{d}/no/such/dir/p.json"], "does not exist"),
    (["calibrate", "{d}/log.csv", "-o", "{d}/path.csv"], "exists; pass --force"),
    (["demo", "--out", "{d}/log.csv", "--cycles", "1"], "is not a directory"),
    (["dem", "sanity", "--data", "{d}"], "no manifest.json"),
])
def test_bad_outputs_are_refused_before_any_work(tmp_path, files, capsys, argv, message):
    _copy_inputs(files, tmp_path)
    before = _snapshot(tmp_path)
    code = main([a.format(d=tmp_path) for a in argv])
    assert code == 2
    assert message in _one_error_line(capsys)
    assert _snapshot(tmp_path) == before  # nothing written, nothing lost


def test_a_full_disk_in_the_middle_of_a_write_keeps_the_old_file(tmp_path, files, capsys, monkeypatch):
    _copy_inputs(files, tmp_path)
    out = tmp_path / "params.json"
    old = out.read_bytes()
    real = Path.write_text

    def full_disk(self, data, *args, **kwargs):
        real(self, data[: len(data) // 2], *args, **kwargs)  # half of it reaches the disk
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))

    monkeypatch.setattr(Path, "write_text", full_disk)
    code = main(["calibrate", str(tmp_path / "log.csv"), "-o", str(out), "--force"])
    assert code == 2
    assert "No space left on device" in _one_error_line(capsys)
    assert out.read_bytes() == old
    assert not [p for p in tmp_path.iterdir() if ".partial-" in p.name]


def test_a_read_only_directory_is_a_clear_error(tmp_path, files, capsys, monkeypatch):
    _copy_inputs(files, tmp_path)
    out_dir = tmp_path / "ro"
    out_dir.mkdir()
    if os.geteuid() == 0:  # root writes anywhere: make the rename fail as it would for a user
        def refused(src, dst):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(dst))

        monkeypatch.setattr("wheelloader.cli.output.os.replace", refused)
    else:
        out_dir.chmod(0o555)
    try:
        code = main(["predict", "gravel", str(tmp_path / "path.csv"), "-o", str(out_dir / "f.csv")])
    finally:
        out_dir.chmod(0o755)
    assert code == 2
    assert "Permission denied" in _one_error_line(capsys)
    assert list(out_dir.iterdir()) == []


def test_force_and_its_old_name_overwrite_in_every_subcommand(tmp_path, files, capsys):
    _copy_inputs(files, tmp_path)
    out = tmp_path / "forces.csv"
    out.write_text("old\n")
    assert main(["predict", "gravel", str(tmp_path / "path.csv"), "-o", str(out), "--force"]) == 0
    out.write_text("old\n")
    assert main(["predict", "gravel", str(tmp_path / "path.csv"), "-o", str(out), "--overwrite"]) == 0
    assert out.read_text().startswith("t,")
    from wheelloader.cli import build_parser

    parser = build_parser()
    for command in (["calibrate", "x.csv"], ["predict", "p", "x.csv"], ["plan", "gravel"], ["demo"]):
        assert parser.parse_args([*command, "--force"]).force is True


def test_check_outputs_and_atomic_output(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.png"
    assert check_outputs([("-o", a), ("--plot", None), ("--x", b)], [tmp_path / "in.csv"]) == [a, b]
    a.write_text("keep")
    with pytest.raises(ParameterError, match="exists; pass --force"):
        check_outputs([("-o", a)])
    with pytest.raises(RuntimeError):
        with atomic_output(a) as tmp:
            tmp.write_text("half")
            raise RuntimeError("crash")
    assert a.read_text() == "keep" and sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]
    write_json(a, {"x": float("nan"), "y": [1.0, float("inf")]})
    assert json.loads(a.read_text()) == {"x": None, "y": [1.0, None]}


def test_help_imports_no_optimiser_or_plotting():
    """``wheelloader --help`` builds every parser without importing the estimator, scipy or matplotlib."""
    import subprocess
    import sys

    code = ("import sys\nfrom wheelloader.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('scipy', 'matplotlib', 'casadi', 'wheelloader.estimator') if m in sys.modules]\n"
            "assert not heavy, heavy\n")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def test_envs_and_planner_import_no_optimiser():
    """``import wheelloader.envs`` (and the planner) leave calibration and SciPy's optimisers unimported until a
    calibration name is used; then ``wheelloader.estimator`` re-exports it as before."""
    import subprocess
    import sys

    code = ("import sys\nimport wheelloader.envs, wheelloader.planner\n"
            "heavy = [m for m in ('scipy.optimize', 'scipy.ndimage', 'wheelloader.estimator.calibration')"
            " if m in sys.modules]\nassert not heavy, heavy\n"
            "from wheelloader.estimator import calibrate, Calibration\n"
            "import wheelloader.estimator.calibration as c\nassert calibrate is c.calibrate\n"
            "assert 'load_params' in dir(sys.modules['wheelloader.estimator'])\n")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def test_help_texts_are_plain_text_and_name_every_pile_kind():
    """Every ``--help`` of the command line reads as plain text (no reST roles or literals), and ``--pile``
    lists every pile preset the commands accept."""
    import argparse
    import re

    from wheelloader.cli import build_parser
    from wheelloader.cli.inputs import PILE_PRESETS

    def parsers(parser):
        yield parser
        for action in parser._actions:  # noqa: SLF001 - argparse has no public list of subparsers
            if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
                for sub in action.choices.values():
                    yield from parsers(sub)

    seen = 0
    for parser in parsers(build_parser()):
        text = parser.format_help()
        assert not re.search(r"``|:(func|class|mod|meth|attr|data):`", text), text
        if "--pile" in text:
            pile_help = next(a.help for a in parser._actions if "--pile" in a.option_strings)  # noqa: SLF001
            assert all(kind in pile_help for kind in PILE_PRESETS), pile_help
            seen += 1
    assert seen >= 2  # predict and plan
