"""Prediction bands: parameter covariance + residual noise model, coverage on known noise, JSON round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wheelloader.cli import main
from wheelloader.estimator import ParameterError, preset
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.calibration.bands import BandModel, normal_quantile, residual_noise_model
from wheelloader.estimator.synthetic import random_bezier_path, synthetic_cycle


def test_normal_quantile_and_bad_levels():
    assert normal_quantile(0.9) == pytest.approx(1.6449, abs=1e-4)
    for bad in (0.0, 1.0, 1.5, True, "0.9"):
        with pytest.raises(ParameterError):
            normal_quantile(bad)


def test_residual_noise_model_recovers_floor_and_relative_part():
    rng = np.random.default_rng(0)
    pred = rng.uniform(0.0, 5000.0, 20000)
    obs = pred + rng.normal(0.0, 1.0, pred.size) * np.sqrt(100.0**2 + (0.1 * pred) ** 2)
    sigma_0, rel = residual_noise_model(obs, pred)
    assert sigma_0 == pytest.approx(100.0, rel=0.15) and rel == pytest.approx(0.1, rel=0.05)
    assert residual_noise_model(pred, pred) == (0.0, 0.0)


@pytest.mark.parametrize("soil_name", ["gravel", "dirt"])
def test_band_covers_white_noise_at_its_level(soil_name):
    """With white noise and the true model, the 90 % band covers about 90 % of a new noisy cycle."""
    rng = np.random.default_rng(4)
    train = synthetic_cycle(soil_name, random_bezier_path(rng), noise=0.05, seed=1, force_scale=2000.0)
    test = synthetic_cycle(soil_name, random_bezier_path(rng), noise=0.05, seed=2, force_scale=2000.0)
    cal = calibrate(train)
    pred = predict(cal, test, band=0.9)
    mask = pred.state.depth > 0.0
    cover = pred.band.coverage(test.resultant, mask)
    assert 0.8 <= cover <= 0.97, cover
    assert np.all(pred.band.upper_r >= pred.resultant) and np.all(pred.band.lower_r <= pred.resultant)
    wider = predict(cal, test, band=0.99).band
    assert np.all(wider.upper_r >= pred.band.upper_r)


def test_band_model_round_trip_and_errors(tmp_path):
    cal = calibrate(synthetic_cycle("sand", noise=0.05, seed=3))
    model = cal.band_model
    again = BandModel.from_dict(json.loads(json.dumps(model.to_dict())))
    np.testing.assert_array_equal(np.isnan(again.covariance), np.isnan(model.covariance))
    assert again.tau == model.tau and again.sigma_0 == model.sigma_0
    with pytest.raises(ParameterError, match="needs a Calibration"):
        predict(preset("sand"), synthetic_cycle("sand", noise=0.0), band=0.9)
    with pytest.raises(ParameterError, match="band model"):
        BandModel.from_dict({"covariance": [[1.0]], "tau": 1, "sigma_0_N": 0, "relative": 0})


def test_cli_predict_draws_the_band(tmp_path, capsys):
    rng = np.random.default_rng(5)
    log, other = tmp_path / "log.csv", tmp_path / "other.csv"
    synthetic_cycle("dirt", random_bezier_path(rng), noise=0.05, seed=1).save(log)
    synthetic_cycle("dirt", random_bezier_path(rng), noise=0.05, seed=2).save(other)
    params = tmp_path / "params.json"
    assert main(["calibrate", str(log), "-o", str(params)]) == 0
    capsys.readouterr()
    out_csv, fig = tmp_path / "f.csv", tmp_path / "f.png"
    assert main(["predict", str(params), str(other), "-o", str(out_csv), "--plot", str(fig)]) == 0
    text = capsys.readouterr().out
    assert "90% prediction band" in text and "covers" in text
    assert "F_R_upper" in out_csv.read_text().splitlines()[0] and fig.stat().st_size > 0
    assert main(["predict", "dirt", str(other), "-o", str(tmp_path / "g.csv")]) == 0
    assert "no prediction band" in capsys.readouterr().out


def test_cross_cycle_band_noise_uses_held_out_residuals():
    """Leave one cycle out: the noise model sees residuals of cycles the fit did not see (here: another soil)."""
    rng = np.random.default_rng(8)
    logs = [synthetic_cycle(name, random_bezier_path(rng), noise=0.03, seed=k, force_scale=2000.0)
            for k, name in enumerate(("gravel", "gravel", "dirt"))]
    train = calibrate(logs)
    cross = calibrate(logs, options=CalibrationOptions(band_noise="cross-cycle"))
    assert cross.settings["band_noise"] == "cross-cycle" and "band_noise" not in train.settings
    np.testing.assert_array_equal(cross.params.to_array(), train.params.to_array())  # the fit is the same
    f_r = np.hypot(train.predicted_tangential, train.predicted_normal)[train.in_soil]
    mean_var = lambda m: float(np.mean(m.sigma_0 ** 2 + (m.relative * f_r) ** 2))  # noqa: E731
    assert mean_var(cross.band_model) > mean_var(train.band_model)
    with pytest.raises(Exception, match="band_noise"):
        calibrate(logs, options=CalibrationOptions(band_noise="loo"))
