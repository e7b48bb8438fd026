"""The loop's calibration prior at the nominal soil (``wheelloader.adaptation.LoopPrior``, issue #32 item 4)."""

import argparse
import math

import pytest

import wheelloader.adaptation as adaptation
from wheelloader.adaptation import DEFAULT_PRIOR, PRIOR_NAMES, Calibrating, LoopPrior, hidden_default_soil
from wheelloader.demo import DEMO_PRIOR, run_demo
from wheelloader.estimator import Pile, WheelloaderError, preset
from wheelloader.estimator.calibration import HeldPrior
from wheelloader.loop import run_loop
from wheelloader.references.fee_env import FEEEnvPlant


def test_no_prior_holds_nothing_and_nominal_holds_gamma_k_n_softly_at_the_soil():
    sand = preset("sand")
    assert LoopPrior("none").held(sand, 0.02) is None
    held = LoopPrior("nominal").held(sand, 0.02)
    assert isinstance(held, HeldPrior)
    assert held.free_one == ("cohesion", "adhesion", "phi", "delta")
    assert held.mean["gamma"] == pytest.approx(sand.gamma)
    assert held.mean["K"] == pytest.approx(sand.sinkage_modulus(0.02))
    assert held.std == pytest.approx({"gamma": 0.1 * sand.gamma, "K": 0.3 * sand.sinkage_modulus(0.02), "n": 0.15})
    gravel = LoopPrior("nominal").held(preset("gravel"), 0.02)
    assert gravel.mean["n"] == pytest.approx(preset("gravel").n) != pytest.approx(sand.n)


@pytest.mark.parametrize("bad", [{"mode": "sand"}, {"mode": "nominal", "gamma_rel": 0.0},
                                 {"mode": "nominal", "n_std": float("nan")}, {"mode": "nominal", "k_rel": -1.0}])
def test_bad_prior_settings_are_refused(bad):
    with pytest.raises(WheelloaderError):
        LoopPrior(**bad)


def test_calibrating_passes_the_prior_at_its_prior_soil(monkeypatch):
    seen = []
    real = adaptation.calibrate

    def spy(cycles, options):
        seen.append(options.held)
        return real(cycles, options=options)

    monkeypatch.setattr(adaptation, "calibrate", spy)
    gravel = preset("gravel")
    for prior, soil in (("none", None), ("nominal", None), ("nominal", gravel)):
        seen.clear()
        strategy = Calibrating(preset("sand"), prior=prior, prior_soil=soil)
        records, _ = run_loop(FEEEnvPlant(keep_env=True), strategy, Pile.trapezoid(), hidden_default_soil(), 2,
                              seed=0)
        assert len(seen) == 1 and all(r.calibration_ok for r in records)  # after cycle 1, before cycle 2
        want = LoopPrior(prior).held(soil or preset("sand"), 0.02)
        assert all(h == want for h in seen)


def test_the_demo_cli_offers_the_prior_names():
    from wheelloader.cli import demo

    parser = argparse.ArgumentParser()
    demo.register(parser.add_subparsers())
    args = parser.parse_args(["demo", "--prior", "nominal"])
    assert args.prior == "nominal"
    assert [parser.parse_args(["demo", "--prior", name]).prior for name in PRIOR_NAMES] == list(PRIOR_NAMES)
    assert DEFAULT_PRIOR in PRIOR_NAMES and DEMO_PRIOR in PRIOR_NAMES
    assert parser.parse_args(["demo"]).prior is None  # run_demo's default: DEMO_PRIOR
    with pytest.raises(SystemExit):
        parser.parse_args(["demo", "--prior", "sand"])


def test_the_demo_holds_its_prior_and_records_it(tmp_path, monkeypatch):
    seen = []
    real = adaptation.calibrate

    def spy(cycles, options):
        seen.append(options.held)
        return real(cycles, options=options)

    monkeypatch.setattr(adaptation, "calibrate", spy)
    (tmp_path / "demo").mkdir()
    summary = run_demo(tmp_path / "demo", cycles=2, use_planner=False)
    assert DEMO_PRIOR == "nominal" and summary["calibration_prior"] == DEMO_PRIOR
    assert seen == [LoopPrior("nominal").held(preset(adaptation.NOMINAL_SOIL), 0.02)]
    with pytest.raises(WheelloaderError, match="prior"):
        run_demo(tmp_path / "bad", cycles=1, use_planner=False, prior="sand")


def test_held_prior_holds_all_seven_softly_and_names_resolve():
    from wheelloader.loop_prior import HELD_PRIOR, LOOP_PRIORS, loop_prior

    sand = preset("sand")
    held = loop_prior("held").held(sand, 0.02)
    assert loop_prior("held") is HELD_PRIOR and held.free_one == ()
    assert held.mean["phi"] == pytest.approx(sand.phi) and held.mean["cohesion"] == pytest.approx(0.0)
    assert held.std["phi"] == pytest.approx(math.radians(5.0)) and held.std["adhesion"] == pytest.approx(1000.0)
    assert set(held.std) == {"gamma", "K", "n", "phi", "delta", "cohesion", "adhesion"}
    assert loop_prior("nominal") == LoopPrior("nominal") and loop_prior("none").held(sand, 0.02) is None
    assert set(LOOP_PRIORS) >= set(PRIOR_NAMES)
    with pytest.raises(WheelloaderError):
        loop_prior("sand")
    with pytest.raises(WheelloaderError):
        LoopPrior("nominal", phi_std=-1.0)


def test_plant_loop_unit_calibrates_ours_with_the_named_prior(tmp_path, monkeypatch):
    from wheelloader.loop import plant_loop_unit
    from wheelloader.loop_prior import HELD_PRIOR

    seen = []
    real = adaptation.calibrate

    def spy(cycles, options):
        seen.append(options.held)
        return real(cycles, options=options)

    monkeypatch.setattr(adaptation, "calibrate", spy)
    out = plant_loop_unit(FEEEnvPlant(sensor_noise=0.0), "ours", "gravel", cycles=2, seed=0, cache=None,
                          planner=False, failure_angle="min_weight_force", prior="held")
    assert out["records"][1]["calibration_ok"]
    assert seen == [HELD_PRIOR.held(preset(adaptation.NOMINAL_SOIL), 0.02)]  # calibrated after cycle 1
