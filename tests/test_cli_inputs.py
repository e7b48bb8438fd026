"""The audit's input classes through ``wheelloader calibrate`` and ``predict`` (#13).

Each broken log gives exit status 2 and one ``wheelloader: error:`` line naming the problem, never a
traceback, and writes nothing. A few inputs are not errors (CRLF line ends, extra columns): those must
calibrate.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from wheelloader.cli import main
from wheelloader.estimator import synthetic_cycle


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> tuple[list[str], list[list[str]], str]:
    """Header, rows and sidecar text of a valid noise-free log."""
    d = tmp_path_factory.mktemp("good")
    synthetic_cycle("gravel", noise=0.0).save(d / "log.csv")
    lines = [ln for ln in (d / "log.csv").read_text().splitlines() if ln and not ln.startswith("#")]
    header = lines[0].split(",")
    rows = [ln.split(",") for ln in lines[1:]]
    return header, rows, (d / "log.json").read_text()


def _write(tmp_path: Path, header: list[str], rows: list[list[str]], sidecar: str, *, newline: str = "\n",
           encoding: str = "utf-8") -> Path:
    csv_path = tmp_path / "log.csv"
    text = newline.join([",".join(header), *(",".join(r) for r in rows)]) + newline
    csv_path.write_bytes(text.encode(encoding))
    (tmp_path / "log.json").write_text(sidecar)
    return csv_path


def _column(header: list[str], name: str) -> int:
    return header.index(name)


def _mutate(kind: str, header: list[str], rows: list[list[str]]) -> tuple[list[str], list[list[str]]]:
    header, rows = list(header), [list(r) for r in rows]
    if kind == "missing column":
        k = _column(header, "F_N")
        return header[:k] + header[k + 1:], [r[:k] + r[k + 1:] for r in rows]
    if kind == "swapped x and z":
        i, j = _column(header, "x"), _column(header, "z")
        header[i], header[j] = header[j], header[i]
        return header, rows
    if kind in ("NaN", "inf"):
        rows[10][_column(header, "F_T")] = "nan" if kind == "NaN" else "inf"
        return header, rows
    if kind == "empty":
        return [], []
    if kind == "header only":
        return header, []
    if kind == "one row":
        return header, rows[:1]
    if kind == "time not increasing":
        k = _column(header, "t")
        rows[20][k], rows[21][k] = rows[21][k], rows[20][k]
        return header, rows
    if kind == "angles in degrees":
        k = _column(header, "blade_angle")
        for r in rows:
            r[k] = repr(math.degrees(float(r[k])))
        return header, rows
    if kind == "1e30 forces":
        for name in ("F_T", "F_N"):
            k = _column(header, name)
            for r in rows:
                r[k] = repr(float(r[k]) * 1e30)
        return header, rows
    if kind == "text in a number":
        rows[5][_column(header, "z")] = "abc"
        return header, rows
    raise AssertionError(kind)


@pytest.mark.parametrize("kind, message", [
    ("missing column", "F_N"),
    ("swapped x and z", ""),
    ("NaN", "NaN"),
    ("inf", "inf"),
    ("empty", "empty"),
    ("header only", "at least 2 data rows"),
    ("one row", "at least 2 data rows"),
    ("time not increasing", "increasing"),
    ("angles in degrees", "degrees"),
    ("text in a number", "not a number"),
])
def test_broken_logs_are_one_line_errors(tmp_path, good, capsys, kind, message):
    header, rows, sidecar = good
    header, rows = _mutate(kind, header, rows)
    log = _write(tmp_path, header, rows, sidecar)
    out = tmp_path / "params.json"
    code = main(["calibrate", str(log), "-o", str(out)])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if kind == "swapped x and z":
        # the geometry check of the sidecar may not see it; then the calibration must not be trusted
        if code == 2:
            assert err.startswith("wheelloader: error: ") and len(err.strip().splitlines()) == 1
            return
        assert code in (0, 1)
        return
    assert code == 2, (kind, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("wheelloader: error: "), err
    assert message.lower() in lines[0].lower(), (kind, lines[0])
    assert not out.exists()


@pytest.mark.parametrize("variant", ["CRLF", "extra column"])
def test_harmless_variants_calibrate(tmp_path, good, capsys, variant):
    header, rows, sidecar = good
    if variant == "extra column":
        header = [*header, "engine_rpm"]
        rows = [[*r, "1500"] for r in rows]
    log = _write(tmp_path, header, rows, sidecar, newline="\r\n" if variant == "CRLF" else "\n")
    out = tmp_path / "params.json"
    assert main(["calibrate", str(log), "-o", str(out)]) == 0, capsys.readouterr().err
    assert json.loads(out.read_text())["calibration"]["success"] is True


@pytest.mark.parametrize("encoding, message", [("utf-16", "UTF-8"), ("binary", "UTF-8")])
def test_wrong_encodings(tmp_path, good, capsys, encoding, message):
    header, rows, sidecar = good
    if encoding == "binary":
        log = tmp_path / "log.csv"
        log.write_bytes(bytes(range(256)) * 16)
        (tmp_path / "log.json").write_text(sidecar)
    else:
        log = _write(tmp_path, header, rows, sidecar, encoding=encoding)
    assert main(["calibrate", str(log), "-o", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


def _scaled_forces(tmp_path, good, scale):
    header, rows, sidecar = good
    for name in ("F_T", "F_N"):
        k = _column(header, name)
        for r in rows:
            r[k] = repr(float(r[k]) * scale)
    return _write(tmp_path, header, rows, sidecar)


def test_forces_on_no_loader_s_scale_are_refused(tmp_path, good, capsys):
    """Forces scaled by 1e30: refused naming the likely unit (estimator/plausibility.py), nothing written."""
    log = _scaled_forces(tmp_path, good, 1e30)
    assert main(["calibrate", str(log), "-o", str(tmp_path / "p.json")]) == 2
    assert "forces look like mN" in capsys.readouterr().err
    assert not (tmp_path / "p.json").exists()


@pytest.mark.parametrize("scale", [0.0])
def test_degenerate_forces_are_flagged_and_strict_fails(tmp_path, good, capsys, scale):
    """Forces all zero: calibrated, but called untrustworthy; --strict exits 1."""
    log = _scaled_forces(tmp_path, good, scale)
    code = main(["calibrate", str(log), "-o", str(tmp_path / "p.json")])
    out = capsys.readouterr().out
    assert "NOT trustworthy" in out and "--strict" in out
    assert main(["calibrate", str(log), "-o", str(tmp_path / "p.json"), "--force", "--strict"]) == 1
    assert code in (0, 1)
    saved = json.loads((tmp_path / "p.json").read_text())
    assert saved["calibration"]["trustworthy"] is False


def test_unphysical_parameters_warn_or_fail_with_strict(tmp_path, good, capsys):
    from wheelloader.estimator import preset

    header, rows, sidecar = good
    log = _write(tmp_path, header, rows, sidecar)
    params = tmp_path / "odd.json"
    params.write_text(json.dumps(preset("gravel").to_dict() | {"gamma": 1.0e6, "cohesion": 1.0e9}))
    assert main(["predict", str(params), str(log), "-o", str(tmp_path / "f.csv")]) == 0
    err = capsys.readouterr().err
    assert "outside the physical domain" in err and "gamma" in err and "--strict" in err
    code = main(["predict", str(params), str(log), "-o", str(tmp_path / "g.csv"), "--strict"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("wheelloader: error: ") and "gamma" in err[0]
    assert not (tmp_path / "g.csv").exists()
    assert main(["calibrate", str(log), "-o", str(tmp_path / "p.json"), "--initial", str(params), "--strict"]) == 2
    assert main(["plan", str(params), "-o", str(tmp_path / "plan.csv"), "--strict"]) == 2


def test_a_compressed_saved_cycle_is_recognised_as_a_cycle_log(tmp_path):
    """A saved loop cycle (``.csv.xz`` + ``.json.xz``) is a cycle log to the CLI, as its plain form is."""
    import shutil

    from wheelloader.cli.inputs import is_cycle_log

    source = Path(__file__).resolve().parents[1] / "data" / "results" / "adaptation_mpm" / "cycles" / "gravel"
    for name in ("cycle1.csv.xz", "cycle1.json.xz"):
        shutil.copy(source / "seed0" / "ours" / name, tmp_path / name)
    assert is_cycle_log(tmp_path / "cycle1.csv.xz")
    (tmp_path / "cycle1.json.xz").unlink()
    assert not is_cycle_log(tmp_path / "cycle1.csv.xz")
    (tmp_path / "broken.csv.xz").write_bytes(b"not xz")
    (tmp_path / "broken.json.xz").write_bytes(b"not xz")
    assert not is_cycle_log(tmp_path / "broken.csv.xz")
