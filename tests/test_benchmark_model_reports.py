"""``benchmarks/error_analysis.py`` and ``benchmarks/paper_experiments.py`` with ``--force-models``: every model
side by side on a tiny reference set (two MPM cycles), figures equal to a direct calibrate/predict."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from benchmark_scripts import load_benchmark

ROOT = Path(__file__).resolve().parents[1]
CYCLES = ("gravel_path1", "gravel_path2")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    """A reference directory with two cycles of data/mpm and their manifest entries."""
    src = ROOT / "data" / "mpm"
    manifest = json.loads((src / "manifest.json").read_text())
    out = tmp_path_factory.mktemp("mpm")
    manifest["cycles"] = [c for c in manifest["cycles"] if c["name"] in CYCLES]
    assert len(manifest["cycles"]) == len(CYCLES)
    for name in CYCLES:
        for ext in ("csv", "json"):
            shutil.copy(src / f"{name}.{ext}", out / f"{name}.{ext}")
    (out / "manifest.json").write_text(json.dumps(manifest))
    return out


def _direct(data: Path, train: str, test: str, force_model: str):
    from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
    from wheelloader.references import dem

    cal = calibrate(dem.filtered(dem.load_reference(train, data), 0.1),
                    options=CalibrationOptions(force_model=force_model))
    raw = dem.load_reference(test, data)
    return predict(cal, dem.filtered(raw, 0.1)), predict(cal, raw)


@pytest.fixture(scope="module")
def error_run(tiny, tmp_path_factory):
    out = tmp_path_factory.mktemp("error")
    assert load_benchmark("error_analysis").main(["--data", str(tiny), "--out", str(out),
                                         "--force-models", "fee", "fee-payload"]) == 0
    return json.loads((out / "error_analysis.json").read_text()), out


def test_error_analysis_runs_each_model_side_by_side(tiny, error_run):
    result, out = error_run
    assert result["force_models"] == ["fee", "fee-payload"] and result["learned_artifact"] is None
    assert [c["test"] for c in result["cases"]] == list(CYCLES)
    for case in result["cases"]:
        assert list(case["models"]) == ["fee", "fee-payload"]
        for name, entry in case["models"].items():
            pred, pred_raw = _direct(tiny, case["train"], case["test"], name)
            assert entry["rmse_percent"] == pytest.approx(pred.quality.percent_r, rel=1e-9)
            assert entry["rmse_percent_unfiltered"] == pytest.approx(pred_raw.quality.percent_r, rel=1e-9)
            shares = sum(p.get("share_of_squared_error", 0.0) for p in entry["phases"].values())
            assert shares == pytest.approx(1.0)
        fee, payload = case["models"]["fee"], case["models"]["fee-payload"]
        # the FEE has no force once the tip leaves the soil; the payload model carries its kept soil
        assert fee["after_exit"]["samples"] > 0 and fee["after_exit"]["mean_predicted_F_R"] == 0.0
        assert payload["after_exit"]["mean_predicted_F_R"] > 0.0
        assert "carried load (missing)" in fee["phases"]["entry"]["residual_share_explained_by_term"]
        assert "carried load (model)" in payload["phases"]["entry"]["residual_share_explained_by_term"]
        assert len(case["series"]["t"]) == len(payload["series"]["pred_R"])
    assert "| fee in soil | fee-payload in soil |" in (out / "error_analysis.md").read_text()
    assert (out / "phases.png").stat().st_size > 0 and (out / "terms.png").stat().st_size > 0


def test_learned_terms_add_up_to_the_prediction_after_exit(tiny):
    """Out of soil the FEE terms vanish: fee-learned's force is its carried load plus its correction."""
    from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
    from wheelloader.estimator.learned import DEFAULT_ARTIFACT
    from wheelloader.references import dem

    module = load_benchmark("error_analysis")
    log = dem.filtered(dem.load_reference("gravel_path1", tiny), 0.1)
    cal = calibrate(log, options=CalibrationOptions(force_model="fee-learned"))
    pred = predict(cal, log)
    terms = module.term_forces(pred, log.bucket, 1500.0, cal.model_options.contact_depth, "fee-learned",
                               cal.model_options)
    assert set(terms) == set(module.LEARNED_TERMS)
    out = pred.state.depth <= 0.0
    assert np.count_nonzero(out) > 10
    for k, force in enumerate((pred.forces.tangential, pred.forces.normal)):
        total = terms["carried load (model)"][k] + terms["learned correction"][k]
        np.testing.assert_allclose(total[out], force[out], rtol=1e-9, atol=1e-6)
    art = module.learned_artifact()
    assert art["sha256"] == hashlib.sha256(Path(DEFAULT_ARTIFACT).read_bytes()).hexdigest()


def test_paper_experiments_force_models_beside_the_method_tables(tiny, tmp_path):
    module = load_benchmark("paper_experiments")
    assert module.main(["--data", str(tiny), "--out", str(tmp_path), "--methods", "default",
                        "--no-estimator-study", "--force-models", "fee", "fee-learned"]) == 0
    results = json.loads((tmp_path / "results.json").read_text())
    models = results["force_models"]
    assert list(models) == ["fee", "fee-learned"]
    # the FEE column is the method table's own calibration
    assert models["fee"]["Table 3: gravel path 1 (training)"]["filtered"] == results["table3"]["default"]["train"][
        "filtered"]
    assert models["fee"]["Fig. 8: gravel path2 (unseen)"]["unfiltered"] == results["fig8"]["default"]["path2"][
        "unfiltered"]
    pred, pred_raw = _direct(tiny, "gravel_path1", "gravel_path2", "fee-learned")
    entry = models["fee-learned"]["Fig. 8: gravel path2 (unseen)"]
    assert entry["filtered"][1] == pytest.approx(pred.quality.percent_r, rel=1e-9)
    assert entry["unfiltered"][1] == pytest.approx(pred_raw.quality.percent_r, rel=1e-9)
    assert results["learned_artifact"]["version"]
    assert "| case | target (filtered) | fee | fee-learned |" in (tmp_path / "summary.md").read_text()
    assert (tmp_path / "fig_models.png").stat().st_size > 0


@pytest.mark.parametrize("name", ["error_analysis", "paper_experiments"])
def test_an_unknown_force_model_is_refused(name, tiny, tmp_path, capsys):
    assert load_benchmark(name).main(["--data", str(tiny), "--out", str(tmp_path / "out"), "--force-models", "fee",
                             "bogus"]) == 2
    assert "wheelloader: error: unknown force model 'bogus'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
