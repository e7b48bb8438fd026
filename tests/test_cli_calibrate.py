"""``wheelloader calibrate`` and ``wheelloader predict`` end to end."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from wheelloader.cli import main
from wheelloader.estimator import paper_paths, preset
from wheelloader.estimator.cyclelog import save_path_csv
from wheelloader.estimator.synthetic import synthetic_cycle


@pytest.fixture()
def log_csv(tmp_path):
    path = tmp_path / "log.csv"
    synthetic_cycle("lean_clay", noise=0.0).save(path)
    return path


def _read(csv_path):
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def test_calibrate_then_predict(tmp_path, log_csv, capsys):
    params = tmp_path / "params.json"
    plot = tmp_path / "cal.png"
    assert main(["calibrate", str(log_csv), "-o", str(params), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "ms" in out and "RMSE F_T" in out and "identifiability" in out
    data = json.loads(params.read_text())
    assert data["soil"]["gamma"] == pytest.approx(preset("lean_clay").gamma, rel=1e-6)
    assert data["calibration"]["success"] is True
    assert plot.stat().st_size > 0

    # predict on a new path without a log (default trapezoid pile)
    path_csv = tmp_path / "path2.csv"
    save_path_csv(paper_paths()[1], path_csv)
    forces = tmp_path / "forces.csv"
    assert main(["predict", str(params), str(path_csv), "-o", str(forces), "--plot", str(tmp_path / "p.png")]) == 0
    cols = _read(forces)
    truth = synthetic_cycle("lean_clay", paper_paths()[1], noise=0.0)
    np.testing.assert_allclose(cols["F_T"], truth.tangential, rtol=1e-6, atol=1e-3)
    # a bare 8-parameter dict also works
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(preset("lean_clay").to_dict()))
    assert main(["predict", str(bare), str(path_csv), "-o", str(tmp_path / "f2.csv")]) == 0
    # predicting a log prints the RMSE against its measured forces
    assert main(["predict", str(params), str(log_csv), "-o", str(tmp_path / "f3.csv")]) == 0
    assert "RMSE" in capsys.readouterr().out


def test_predict_with_pile_json(tmp_path, log_csv):
    cyc = synthetic_cycle("dirt", noise=0.0)
    pile_json = tmp_path / "pile.json"
    pile_json.write_text(json.dumps(cyc.pile_after.to_dict()))
    path_csv = tmp_path / "path.csv"
    save_path_csv(cyc.path.shifted(dx=0.15), path_csv)
    out = tmp_path / "f.csv"
    assert main(["predict", "dirt", str(path_csv), "-o", str(out), "--pile", str(pile_json)]) == 0
    assert _read(out)["depth"].max() > 0


def test_paper_method_and_errors(tmp_path, log_csv, capsys):
    params = tmp_path / "p.json"
    code = main(["calibrate", str(log_csv), "--method", "multi-stage", "-o", str(params)])
    assert code in (0, 1)  # 1 = ran but did not converge; the message says so
    assert json.loads(params.read_text())["calibration"]["method"] == "multi-stage"
    # existing output is not overwritten silently
    assert main(["calibrate", str(log_csv), "-o", str(params)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["calibrate", str(tmp_path / "missing.csv")]) == 2
    assert main(["predict", str(params), str(log_csv), "-o", str(tmp_path / "x.csv"), "--pile", "nope"]) == 2
    capsys.readouterr()
    assert main(["calibrate", str(log_csv), "--method", "newton", "-o", str(tmp_path / "n.json")]) == 2
    assert "unknown calibration method 'newton'" in capsys.readouterr().err
    assert not (tmp_path / "n.json").exists()


def test_broken_files_give_clear_errors_not_tracebacks(tmp_path, log_csv, capsys):
    """A new user's broken inputs: exit code 2 and one 'wheelloader: error:' line, never a traceback."""
    binary = tmp_path / "binary.csv"
    binary.write_bytes(bytes(range(128, 256)) * 8)
    binary.with_suffix(".json").write_text(log_csv.with_suffix(".json").read_text())
    params = tmp_path / "params.json"
    params.write_text(json.dumps(preset("dirt").to_dict()))
    bad_json = tmp_path / "bad.json"
    bad_json.write_bytes(b"\xff\xfe garbage")
    cases = [
        (["calibrate", str(binary), "-o", str(tmp_path / "a.json")], "not a UTF-8 text CSV"),
        (["calibrate", str(tmp_path), "-o", str(tmp_path / "b.json")], "is a directory"),
        (["calibrate", str(log_csv), "-o", str(tmp_path / "no" / "dir.json")], "does not exist"),
        (["predict", str(params), str(binary), "-o", str(tmp_path / "c.csv")], "not a UTF-8 text CSV"),
        (["predict", str(params), str(tmp_path), "-o", str(tmp_path / "d.csv")], "is a directory"),
        (["predict", str(bad_json), str(log_csv), "-o", str(tmp_path / "e.csv")], "not a valid JSON file"),
        (["predict", str(params), str(log_csv), "-o", str(tmp_path / "f.csv"), "--pile", str(bad_json)],
         "not a valid JSON file"),
    ]
    for argv, match in cases:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.startswith("wheelloader: error:") and match in err, (argv, err)


def test_calibrate_several_logs(tmp_path, capsys):
    rng = np.random.default_rng(2)
    from wheelloader.estimator.synthetic import random_bezier_path

    logs = []
    for k in range(3):
        path = tmp_path / f"c{k}.csv"
        synthetic_cycle("dirt", random_bezier_path(rng, name=f"c{k}"), noise=0.0).save(path)
        logs.append(str(path))
    params, plot = tmp_path / "p.json", tmp_path / "p.png"
    assert main(["calibrate", *logs, "--forgetting", "0.8", "-o", str(params), "--plot", str(plot)]) == 0
    out = capsys.readouterr().out
    assert "3 cycles fitted together" in out and "what each added cycle determined" in out
    data = json.loads(params.read_text())
    assert data["soil"]["gamma"] == pytest.approx(preset("dirt").gamma, rel=1e-4)
    per = data["calibration"]["settings"]["cycles"]["per_cycle"]
    assert [c["weight"] for c in per] == pytest.approx([0.64, 0.8, 1.0])
    assert plot.stat().st_size > 0
    assert main(["calibrate", *logs, "--method", "multi-stage", "-o", str(tmp_path / "m.json")]) == 2
    assert "varpro method only" in capsys.readouterr().err
    assert main(["calibrate", logs[0], "--forgetting", "0.5", "-o", str(tmp_path / "f.json")]) == 2
