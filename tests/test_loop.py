"""The adaptation loop (wheelloader.loop) on reference plants: the FEE env as plant, resume, metrics, an MPM loop."""

from __future__ import annotations

import json
import lzma
import math
import os
from pathlib import Path

import numpy as np
import pytest

from wheelloader.adaptation import NOMINAL_SOIL, Calibrating, FixedBezier
from wheelloader.estimator import Bucket, BucketPath, CycleLog, Pile, WheelloaderError, preset
from wheelloader.loop import Hindsight, hindsight_parameters, run_loop
from wheelloader.planner import PlanOutcome
from wheelloader.references import Plant
from wheelloader.references.fee_env import FEEEnvPlant
from wheelloader.references.metrics import cycle_work, lifted_work, world_force
from wheelloader.saved_loops import path_digest, path_distance

ROOT = Path(__file__).resolve().parents[1]


def _log(tangential, normal, angle, x, z, t) -> CycleLog:
    p = BucketPath(np.asarray(t, float), np.asarray(x, float), np.asarray(z, float), np.asarray(angle, float))
    return CycleLog(p, np.asarray(tangential, float), np.asarray(normal, float), Pile.trapezoid(), Bucket())


def test_world_force_inverts_the_blade_frame_projection():
    a = np.array([0.0, 0.3, -0.2, 1.0])
    fx, fz = np.array([-100.0, 50.0, 0.0, 20.0]), np.array([30.0, -80.0, 10.0, -5.0])
    tangential = -(fx * np.cos(a) + fz * np.sin(a))
    normal = fx * np.sin(a) - fz * np.cos(a)
    t = np.linspace(0.0, 1.0, 4)
    back = world_force(_log(tangential, normal, a, t, t, t))
    np.testing.assert_allclose(back[0], fx, atol=1e-12)
    np.testing.assert_allclose(back[1], fz, atol=1e-12)


def test_cycle_work_known_answer():
    # the soil pushes back with 1000 N (world -x) while the tip moves +x at 0.5 m/s for 2 s: 1000 J done on it;
    # the blade is flat (a = 0): F_T = -F_x = 1000 N, F_N = -F_z = 0
    t = np.linspace(0.0, 2.0, 121)
    log = _log(np.full_like(t, 1000.0), np.zeros_like(t), np.zeros_like(t), 0.5 * t, np.zeros_like(t), t)
    assert cycle_work(log) == pytest.approx(1000.0, rel=1e-9)
    # a carried 200 N load lifted 0.3 m costs 60 J more (force on the bucket pointing down: F_N = W cos a)
    log2 = _log(np.zeros_like(t), np.full_like(t, 200.0), np.zeros_like(t), np.zeros_like(t), 0.15 * t, t)
    assert cycle_work(log2) == pytest.approx(60.0, rel=1e-9)



def test_lifted_work_adds_the_kept_loads_lift_to_the_common_height():
    # the path ends at 0.3 m; 0.1 m^3 of soil of density 1600 lifted on to 1.2 m: 1600 g 0.1 0.9 J more
    t = np.linspace(0.0, 2.0, 121)
    log = _log(np.zeros_like(t), np.zeros_like(t), np.zeros_like(t), np.zeros_like(t), 0.15 * t, t)
    log.metadata["continuum"] = {"density": 1600.0}
    assert lifted_work(500.0, 0.1, log, 1.2, "gravel") == pytest.approx(500.0 + 1600.0 * 9.81 * 0.1 * 0.9, rel=1e-3)
    # a path ending above the common height is credited the lift it did not need; without the continuum's
    # density the soil preset's gamma is used
    del log.metadata["continuum"]
    assert lifted_work(500.0, 0.1, log, 0.2, "gravel") == pytest.approx(
        500.0 - preset("gravel").gamma * 9.81 * 0.1 * 0.1, rel=1e-3)


def test_fee_env_plant_is_a_plant_and_carves():
    plant = FEEEnvPlant(sensor_noise=0.0)
    assert isinstance(plant, Plant)
    with pytest.raises(TypeError, match="soil"):
        FEEEnvPlant(soil="gravel")


def test_loop_on_the_fee_env_plant_resumes_from_its_cache(tmp_path):
    plant = FEEEnvPlant(sensor_noise=0.0)
    lines: list[str] = []
    records, logs = run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(), "gravel", cycles=2,
                                   cache=tmp_path, progress=lines.append)
    assert [r.cycle for r in records] == [1, 2]
    assert len(lines) == 2 and all("resumed" not in line for line in lines)
    # each cycle starts on the pile the previous one carved, and removed soil from it
    assert logs[1].pile is logs[0].pile_after or np.allclose(logs[1].pile.heights, logs[0].pile_after.heights)
    for r in records:
        assert r.fill_m3 > 0.0 and r.energy_J > 0.0 and math.isfinite(r.prediction_rmse_percent)
    # a second run reads the saved cycles and gives the same records
    again, _ = run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(), "gravel", cycles=2,
                              cache=tmp_path, progress=lines.append)
    assert all("resumed" in line for line in lines[2:])
    for a, b in zip(records, again, strict=True):
        assert a.energy_J == pytest.approx(b.energy_J, rel=1e-9)
        assert a.fill_m3 == pytest.approx(b.fill_m3, rel=1e-9)
    # a cache dug along other paths is refused, never silently reused
    meta = logs[0].metadata
    assert meta["planned_path_sha256"] == path_digest(FixedBezier(preset(NOMINAL_SOIL)).plan(Pile.trapezoid()).path)
    with pytest.raises(WheelloaderError, match="another path"):
        run_loop(plant, FixedBezier(preset(NOMINAL_SOIL), rate=30.0), Pile.trapezoid(), "gravel", cycles=1,
                       cache=tmp_path)
    # ... unless asked to keep it (resuming on another machine): the saved cycle is the one dug, its plan's
    # record is read from the log, and the record says how far the plan made now lies from it
    assert meta["plan"]["ok"] == records[0].plan_ok and meta["plan"]["params"] == records[0].params
    kept_lines: list[str] = []
    kept, _ = run_loop(plant, FixedBezier(preset(NOMINAL_SOIL), rate=30.0), Pile.trapezoid(), "gravel",
                             cycles=2, cache=tmp_path, stale="keep", progress=kept_lines.append)
    assert all("kept saved cycle" in line for line in kept_lines)
    for a, b in zip(records, kept, strict=True):
        assert b.end.startswith("kept saved cycle (path planned now differs by ")
        assert a.energy_J == pytest.approx(b.energy_J, rel=1e-9) and a.plan_message == b.plan_message
        assert a.prediction_rmse_percent == pytest.approx(b.prediction_rmse_percent, rel=1e-9)
    # a log saved before plans were recorded (and before saved cycles were compressed): the record says so
    old_log = CycleLog.load(tmp_path / "cycle1.csv.xz")
    del old_log.metadata["plan"]
    for name in ("cycle1.csv.xz", "cycle1.json.xz"):
        (tmp_path / name).unlink()
    old_log.save(tmp_path / "cycle1.csv")
    older, _ = run_loop(plant, FixedBezier(preset(NOMINAL_SOIL), rate=30.0), Pile.trapezoid(), "gravel",
                              cycles=1, cache=tmp_path, stale="keep")
    assert older[0].end.endswith("its plan's record is that of the plan made now")
    with pytest.raises(WheelloaderError, match="stale"):
        run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(), "gravel", cache=tmp_path,
                       stale="ignore")


def test_path_distance_known_answers():
    path = FixedBezier(preset(NOMINAL_SOIL)).plan(Pile.trapezoid()).path
    assert path_distance(path, path) == 0.0
    shifted = path.shifted(dx=0.01, dz=-0.01)
    assert path_distance(path, shifted) == pytest.approx(0.01 * math.sqrt(2), rel=1e-12)
    shorter = type(path)(t=path.t[: len(path.t) // 2], x=path.x[: len(path.t) // 2], z=path.z[: len(path.t) // 2],
                         blade_angle=path.blade_angle[: len(path.t) // 2])
    assert path_distance(path, shorter) == math.inf


def test_loop_rejects_bad_input():
    plant = FEEEnvPlant()
    with pytest.raises(WheelloaderError, match="cycles"):
        run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(), "gravel", cycles=0)
    with pytest.raises(WheelloaderError, match="Pile"):
        run_loop(plant, FixedBezier(preset(NOMINAL_SOIL)), "trapezoid", "gravel")
    with pytest.raises(WheelloaderError, match="dig"):
        run_loop(object(), FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(), "gravel")


def test_calibrating_strategy_and_hindsight_oracle_on_the_env_plant(tmp_path):
    plant = FEEEnvPlant(sensor_noise=0.0)
    ours = Calibrating(preset(NOMINAL_SOIL), "default", None)  # no planner: Bezier paths, calibration only
    records, logs = run_loop(plant, ours, Pile.trapezoid(), "gravel", cycles=2)
    assert records[1].calibration_ok, records[1].calibration_message
    # calibrated on cycle 1 of the true gravel: cycle 2 is predicted better than with the nominal sand
    assert records[1].prediction_rmse_percent < records[0].prediction_rmse_percent
    params, how = hindsight_parameters(logs)
    assert "cycles" in how
    oracle = Hindsight(params)
    assert oracle.name == "oracle"
    assert oracle.update(logs[0], preset("gravel")).message == "hindsight parameters"
    assert oracle.params == params


def test_tiny_mpm_loop():
    try:
        import taichi  # noqa: F401
    except ImportError:
        if os.environ.get("WHEELLOADER_REQUIRE_MPM") == "1":
            pytest.fail("WHEELLOADER_REQUIRE_MPM=1 but taichi is not installed")
        pytest.skip('taichi not installed: pip install "wheelloader[mpm]"')
    from wheelloader.references.mpm import MPMPlant

    records, logs = run_loop(MPMPlant(resolution=0.08), FixedBezier(preset(NOMINAL_SOIL)), Pile.trapezoid(),
                                   "gravel", cycles=1)
    assert logs[0].metadata["plant"] == "mpm"
    assert records[0].fill_m3 > 0.0 and records[0].energy_J > 0.0
    after = logs[0].pile_after
    assert after is not None
    # the carved pile of a cohesionless soil is handed on relaxed to its friction angle, area conserved (the
    # relaxation's sweeps stop within 1 % of the repose slope; the carved columns stood at up to 6:1)
    slopes = np.abs(np.diff(after.heights)) / after.spacing
    assert slopes.max() <= 1.01 * math.tan(preset("gravel").phi)
    assert logs[0].metadata["settings"]["relax_pile_after"] is True


def test_tiny_mpm_loop_of_ours_with_the_kept_objective(tmp_path):
    """The tiny version of benchmarks/loop_mpm.sh (#33): ours with the kept objective and the run's planner
    settings (the descend clearance, the payload with the curl term of docs/results/transfer), one cycle in an
    8 cm MPM plant through plant_loop_unit; the plan passes its check, ends near the
    dump height, and the cycle is saved and read back (resume)."""
    _need_taichi()
    from wheelloader.loop import plant_loop_unit
    from wheelloader.planner.kept import dump_height
    from wheelloader.references.mpm import MPMPlant

    settings = {"cycles": 1, "seed": 0, "cache": tmp_path / "ours", "failure_angle": "min_weight_force",
                "heel_clearance": 0.0, "end_blade_angle": math.radians(55), "curl_out_intervals": 8,
                "midpoints": False, "objective": "kept_per_energy", "prior": "held", "descend_clearance": 0.1,
                "payload": json.loads((ROOT / "docs/results/transfer/transfer.json").read_text())["payload"]}
    out = plant_loop_unit(MPMPlant(resolution=0.08), "ours", "gravel", **settings)
    record, log = out["records"][0], out["logs"][0]
    assert record["plan_ok"] and "kept" in record["plan_message"] and record["fill_m3"] > 0.0
    # the lift on to the dump height is charged, not constrained: this plan ends 7 cm below it (measured)
    assert abs(float(log.path.z[-1]) - dump_height()) < 0.1
    again = plant_loop_unit(MPMPlant(resolution=0.08), "ours", "gravel", **settings)
    assert again["records"][0]["end"] == "resumed from cache"
    assert again["records"][0]["energy_J"] == record["energy_J"]


def test_env_plant_digs_with_the_loops_end_of_cycle_rule():
    """The env plant ends a cycle on exit only once the bucket holds LOOP_EXIT_MIN_FILL (as the loop's env), so
    a path that leaves the soil early and re-enters is dug in full."""
    from wheelloader.adaptation import LOOP_ENV_KWARGS

    assert FEEEnvPlant().env_kwargs == LOOP_ENV_KWARGS
    assert FEEEnvPlant(exit_min_fill=0.0).env_kwargs["exit_min_fill"] == 0.0  # the caller's setting wins
    # a path that scratches 1 cm into the face, leaves it, then digs: with the loop's rule it is dug to the end
    pile = Pile.trapezoid()
    t = np.linspace(0.0, 6.0, 361)
    x = np.linspace(-0.3, 1.2, t.size)  # the default trapezoid's toe is at x = 0
    z = np.where(x < 0.3, pile.surface_height(x) - 0.01, pile.surface_height(x) - 0.15)
    z[(x > 0.15) & (x < 0.3)] += 0.1
    z = np.maximum(z, -0.2)
    path = BucketPath(t, x, z, np.full_like(t, 0.2))
    full = FEEEnvPlant(sensor_noise=0.0).dig(path, pile, "gravel")
    early = FEEEnvPlant(sensor_noise=0.0, exit_min_fill=0.0).dig(path, pile, "gravel")
    assert full.fill_volume[-1] > 2.0 * early.fill_volume[-1]


def test_plant_loop_unit_builds_ours_with_the_failure_angle_rule(tmp_path):
    from wheelloader.loop import plant_loop_unit

    out = plant_loop_unit(FEEEnvPlant(sensor_noise=0.0), "ours", "gravel", cycles=2, seed=0, cache=tmp_path / "c",
                          planner=False, failure_angle="min_weight_force")
    assert [r["cycle"] for r in out["records"]] == [1, 2] and len(out["logs"]) == 2
    assert out["records"][1]["calibration_ok"]
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["cycle1.csv.xz", "cycle1.json.xz",
                                                                  "cycle2.csv.xz", "cycle2.json.xz"]
    with pytest.raises(WheelloaderError, match="oracle_params"):
        plant_loop_unit(FEEEnvPlant(), "oracle", "gravel", cycles=1, seed=0, cache=None, planner=False)


def test_plant_loop_unit_passes_the_planner_settings_on(monkeypatch):
    import wheelloader.adaptation as adaptation
    from wheelloader.loop import plant_loop_unit

    seen = {}

    class Built(Exception):
        pass

    def fake_planner(**kwargs):
        seen.update(kwargs)
        raise Built

    monkeypatch.setattr(adaptation, "default_planner", fake_planner)
    with pytest.raises(Built):
        plant_loop_unit(FEEEnvPlant(), "ours", "gravel", cycles=1, seed=0, cache=None, midpoints=False,
                        curl_out_intervals=8, heel_clearance=0.0, failure_angle="min_weight_force",
                        objective="kept_per_energy", lookahead=True)
    assert seen["midpoints"] is False and seen["curl_out_intervals"] == 8 and seen["heel_clearance"] == 0.0
    assert seen["failure_angle"] == "min_weight_force"
    assert seen["objective"] == "kept_per_energy" and seen["lookahead"] is True


def test_plant_loop_unit_runs_ours_with_the_learned_model_end_to_end(tmp_path, monkeypatch):
    """``--force-model fee-learned`` (benchmarks/loop_mpm.sh's FORCE_MODEL, #33): ours calibrates with the learned
    correction, its planner is called with that model and the run's payload, and a failed plan falls back to the
    Bezier path placed by the learned model; two cycles on the FEE env plant (the planner stubbed: fast)."""
    import wheelloader.adaptation as adaptation
    from wheelloader.estimator.learned import default_learned_model
    from wheelloader.loop import plant_loop_unit

    calls = []

    def stub_planner(params, pile, **model):
        calls.append(model)
        return PlanOutcome(None, False, "stub: no plan", 0.0)

    monkeypatch.setattr(adaptation, "default_planner", lambda **kwargs: stub_planner)
    payload = json.loads((ROOT / "docs/results/transfer/transfer.json").read_text())["payload"]
    out = plant_loop_unit(FEEEnvPlant(sensor_noise=0.0), "ours", "gravel", cycles=2, seed=0, cache=tmp_path / "c",
                          failure_angle="min_weight_force", prior="held", payload=payload, force_model="fee-learned")
    first, second = out["records"]
    assert second["calibration_ok"] and second["calibration_message"].startswith("F_R fit"), second
    assert [c["force_model"] for c in calls] == ["fee-learned", "fee-learned"]
    assert calls[0]["payload"].to_dict() == pytest.approx(payload)
    assert default_learned_model().payload.to_dict() == pytest.approx(payload)  # the payload fitted with it
    assert not first["plan_ok"] and "fell back" in first["plan_message"] and first["fill_m3"] > 0.0
    # the loop's prediction of each cycle is the learned model's (its error differs from the FEE's on the same log)
    fee = plant_loop_unit(FEEEnvPlant(sensor_noise=0.0), "ours", "gravel", cycles=1, seed=0, cache=tmp_path / "f",
                          failure_angle="min_weight_force", prior="held", payload=payload, force_model="fee-payload")
    assert fee["records"][0]["prediction_rmse_percent"] != pytest.approx(first["prediction_rmse_percent"])


def _need_taichi():
    try:
        import taichi  # noqa: F401
    except ImportError:
        if os.environ.get("WHEELLOADER_REQUIRE_MPM") == "1":
            pytest.fail("WHEELLOADER_REQUIRE_MPM=1 but taichi is not installed")
        pytest.skip('taichi not installed: pip install "wheelloader[mpm]"')


def test_first_cycle_benchmark_fixed_path_smoke(tmp_path, monkeypatch):
    """Smoke run of ``benchmarks/plant_first_cycle.py --quick`` (its whole run is slow, below): only its fixed
    Bezier path, dug at 8 cm in this process; a second run reads the saved cycle instead of digging again. The
    planned variants' constraints are checked in ``tests/test_planner_cut_angle.py``."""
    import importlib.util
    import json
    from pathlib import Path

    _need_taichi()
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "plant_first_cycle.py"
    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_plant_first_cycle", script)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    monkeypatch.setattr(bench, "QUICK", ("fixed Bezier path",))
    for attempt in range(2):
        assert bench.main(["--quick", "--ray", "off", "--out", str(tmp_path)]) == 0
        rows = json.loads((tmp_path / "plant_first_cycle.json").read_text())["rows"]
        assert [r["variant"] for r in rows] == ["fixed Bezier path"]
        assert rows[0]["fill_m3"] > 0.0 and rows[0]["energy_J"] > 0.0
        assert rows[0]["resumed"] == (attempt == 1)
    assert "| fixed Bezier path |" in (tmp_path / "plant_first_cycle.md").read_text()


@pytest.mark.slow
def test_first_cycle_benchmark_quick(tmp_path):
    """``benchmarks/plant_first_cycle.py --quick``: the fixed path and one planner variant dug at 8 cm; a second
    run reads the saved cycles instead of digging again."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    _need_taichi()
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "plant_first_cycle.py"
    for attempt in range(2):
        done = subprocess.run([sys.executable, str(script), "--quick", "--ray", "off", "--out", str(tmp_path)],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        result = json.loads((tmp_path / "plant_first_cycle.json").read_text())
        rows = {r["variant"]: r for r in result["rows"]}
        assert rows["fixed Bezier path"]["fill_m3"] > 0.0 and rows["fixed Bezier path"]["energy_J"] > 0.0
        planned = rows["+ heel clearance, end curled 45°"]
        assert planned["max_heel_depth_m"] <= 0.03 and planned["end_blade_angle_deg"] >= 44.0
        assert all(r["resumed"] == (attempt == 1) for r in result["rows"])
    assert "| fixed Bezier path |" in (tmp_path / "plant_first_cycle.md").read_text()


def test_replay_benchmark_reproduces_the_loops_own_predictions(tmp_path):
    """``benchmarks/plant_replay.py``: its loop-default variant (last cycle, varpro, paper's model) calibrates as
    the loop's ``ours`` does, so on a saved loop of ``ours`` it gives the loop's own next-cycle errors."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    plant = FEEEnvPlant(sensor_noise=0.0)
    ours = Calibrating(preset(NOMINAL_SOIL), "default", None)
    records, _ = run_loop(plant, ours, Pile.trapezoid(), "gravel", cycles=3,
                                cache=tmp_path / "cycles" / "gravel" / "seed0" / "ours")
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "plant_replay.py"
    done = subprocess.run([sys.executable, str(script), "--cycles", str(tmp_path / "cycles"), "--out",
                           str(tmp_path / "out"), "--variants", "ours, last cycle (loop default)",
                           "floor: cycle k fitted to itself (paper's model)"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((tmp_path / "out" / "plant_replay.json").read_text())
    rows = [r for r in result["rows"] if r["variant"] == "ours, last cycle (loop default)"]
    replayed = {r["cycle"]: r["rmse_percent"] for r in rows}
    assert sorted(replayed) == [2, 3]
    for r in records[1:]:
        assert replayed[r.cycle] == pytest.approx(r.prediction_rmse_percent, rel=1e-6)
    markdown = (tmp_path / "out" / "plant_replay.md").read_text()
    assert "| ours, last cycle (loop default) |" in markdown
    # the floor (each cycle fitted to itself) is never worse than that cycle's prediction from the one before
    floor = {r["cycle"]: r["rmse_percent"] for r in result["rows"] if r["variant"].startswith("floor:")}
    assert sorted(floor) == [2, 3]
    assert all(0.0 <= floor[k] <= replayed[k] + 1e-9 for k in floor)
    assert "| floor: cycle k fitted to itself (paper's model) |" in markdown
    # split by the loops' strategy: one loop of ours here, so its median from cycle 3 is cycle 3's error
    split = result["summary"]["ours, last cycle (loop default)"]["median_from_cycle3_per_strategy"]
    assert split == {"ours": {"gravel": pytest.approx(replayed[3])}}
    assert "| calibration | ours: gravel |" in markdown
    # known answer: unfiltered (sigma 1 ms at 60 Hz), a noiseless plant that is the paper's model is fitted by it
    # all but exactly (with the loop's 0.1 s filter not: the filter smooths the plant's force, not the model's)
    raw = subprocess.run([sys.executable, str(script), "--cycles", str(tmp_path / "cycles"), "--out",
                          str(tmp_path / "raw"), "--sigma-s", "0.001", "--variants",
                          "floor: cycle k fitted to itself (paper's model)"],
                         capture_output=True, text=True, timeout=600)
    assert raw.returncode == 0, raw.stderr[-2000:]
    raw_rows = json.loads((tmp_path / "raw" / "plant_replay.json").read_text())["rows"]
    assert len(raw_rows) == 2 and all(r["rmse_percent"] < 1.0 for r in raw_rows)
    # band coverage: counts per prediction, pooled per soil in the summary
    assert all(0 <= r["band_inside"] <= r["band_samples"] and r["band_samples"] > 0 for r in rows)
    pooled = sum(r["band_inside"] for r in rows) / sum(r["band_samples"] for r in rows)
    cover = result["summary"]["ours, last cycle (loop default)"]["band_coverage_per_soil"]["gravel"]
    assert cover["all"] == pytest.approx(pooled)
    assert cover["from_cycle3"] == pytest.approx(rows[1]["band_inside"] / rows[1]["band_samples"])
    # a folder without loops is refused with a clear message
    empty = subprocess.run([sys.executable, str(script), "--cycles", str(tmp_path / "none")], capture_output=True,
                           text=True, timeout=600)
    assert empty.returncode != 0 and "no such folder" in empty.stderr


def test_plant_report_lifts_every_kept_load_to_the_fixed_paths_end_height(tmp_path):
    """``benchmarks/adaptation.py --plant ... --report``: beside the plant's energy per m³, each strategy's energy
    with the load it kept lifted from its end height to the fixed path's (known answer from the saved cycles)."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    plant = FEEEnvPlant(sensor_noise=0.0)
    rows, ends = [], {}
    for name, strategy in (("fixed", FixedBezier(preset(NOMINAL_SOIL))),
                           ("ours", Calibrating(preset(NOMINAL_SOIL), "default", None))):
        records, logs = run_loop(plant, strategy, Pile.trapezoid(), "gravel", cycles=2,
                                       cache=tmp_path / "cycles" / "gravel" / "seed0" / name)
        rows += [dict(r.to_dict(), soil="gravel", seed=0) for r in records]
        ends[name] = [float(log.path.z[-1]) for log in logs]
    settings = {"soils": ["gravel"], "seeds": 1, "cycles": 2, "resolution": 0.02, "ray": "off"}
    result = {"plant": "fee-env", "settings": settings, "rows": rows, "machine": {}, "wall_s": 1.0}
    (tmp_path / "plant_adaptation.json").write_text(json.dumps(result, default=str))
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "adaptation.py"
    done = subprocess.run([sys.executable, str(script), "--plant", "fee-env", "--report", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    z_ref = max(ends["fixed"])
    gamma = preset("gravel").gamma  # the FEE env's logs carry no continuum density: the preset's
    table = (tmp_path / "plant_adaptation.md").read_text()
    for name in ("fixed", "ours"):
        sel = [r for r in rows if r["strategy"] == name]
        lifted = sum(r["energy_J"] + gamma * 9.81 * r["fill_m3"] * (z_ref - z)
                     for r, z in zip(sel, ends[name], strict=True))
        expected = lifted / sum(r["fill_m3"] for r in sel) / 1e3
        raw = sum(r["energy_J"] for r in sel) / sum(r["fill_m3"] for r in sel) / 1e3
        assert expected > raw + 0.1  # cycle 1 ends 0.17 m below cycle 2 (z_ref): a real lift, not a no-op
        mean_end = sum(ends[name]) / len(ends[name])
        assert f"| {expected:.1f} kJ/m³ (ends at {mean_end:.2f} m) |" in table, table
    # without the saved cycles the column is left out, not guessed
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "plant_adaptation.json").write_text(json.dumps(result, default=str))
    again = subprocess.run([sys.executable, str(script), "--plant", "fee-env", "--report", "--out",
                            str(tmp_path / "elsewhere")], capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and "load lifted" not in (tmp_path / "elsewhere" / "plant_adaptation.md").read_text()


class _DeeperBezier(FixedBezier):
    """A strategy that digs the fixed path 5 cm deeper (another path, so another carved pile)."""

    name = "deeper"

    def plan(self, pile):
        outcome = super().plan(pile)
        return PlanOutcome(outcome.path.shifted(dz=-0.05, name="deeper"), True, "deeper Bezier", 0.0)


def test_plant_paired_digs_the_fixed_path_on_each_saved_pile_and_resumes(tmp_path):
    """``benchmarks/plant_paired.py``: it digs the fixed path on the pile each saved cycle started from, in the
    same plant, soil and seed. Known answers: a loop that digs the fixed path itself pairs with its own cycles
    (ratio 1, equal fill); on another strategy's first pile (the fresh pile every loop starts from) the paired dig
    is the fixed loop's first cycle, on its later, differently carved piles it is not; the strategy's side is its
    saved cycles' own measurement; a second invocation reads the dug cycles back."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    plant = FEEEnvPlant()  # the benchmark's --plant fee-env
    measured = {}
    for strategy in (FixedBezier(preset(NOMINAL_SOIL)), _DeeperBezier(preset(NOMINAL_SOIL))):
        records, _ = run_loop(plant, strategy, Pile.trapezoid(), "gravel", cycles=2, seed=1,
                                    cache=tmp_path / "run" / "gravel" / "seed1" / strategy.name)
        measured[strategy.name] = records
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "plant_paired.py"
    command = [sys.executable, str(script), "--plant", "fee-env", "--cycles", str(tmp_path / "run"), "--out",
               str(tmp_path / "out"), "--ray", "off", "--strategies", "fixed", "deeper"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((tmp_path / "out" / "plant_paired.json").read_text())
    rows = {(r["strategy"], r["cycle"]): r for r in result["rows"]}
    assert sorted(rows) == [("deeper", 1), ("deeper", 2), ("fixed", 1), ("fixed", 2)]
    for name in ("fixed", "deeper"):
        for k, record in enumerate(measured[name], start=1):
            assert rows[(name, k)]["strategy_energy_J"] == pytest.approx(record.energy_J, rel=1e-9)
            assert rows[(name, k)]["strategy_fill_m3"] == pytest.approx(record.fill_m3, rel=1e-9)
    for k, record in enumerate(measured["fixed"], start=1):  # the fixed loop paired with itself
        assert rows[("fixed", k)]["fixed_energy_J"] == pytest.approx(record.energy_J, rel=1e-9)
        assert rows[("fixed", k)]["fixed_fill_m3"] == pytest.approx(record.fill_m3, rel=1e-9)
    assert result["summary"]["fixed"]["energy_ratio"] == pytest.approx(1.0, rel=1e-9)
    assert result["summary"]["fixed"]["fill_difference_points_median"] == pytest.approx(0.0, abs=1e-9)
    assert rows[("deeper", 1)]["fixed_energy_J"] == pytest.approx(measured["fixed"][0].energy_J, rel=1e-9)
    assert rows[("deeper", 2)]["fixed_energy_J"] != pytest.approx(measured["fixed"][1].energy_J, rel=1e-3)
    deeper = [rows[("deeper", k)] for k in (1, 2)]
    pooled = (sum(r["strategy_energy_J"] for r in deeper) / sum(r["strategy_fill_m3"] for r in deeper)) / (
        sum(r["fixed_energy_J"] for r in deeper) / sum(r["fixed_fill_m3"] for r in deeper))
    assert result["summary"]["deeper"]["energy_ratio"] == pytest.approx(pooled, rel=1e-12)
    assert "| deeper | 2 |" in (tmp_path / "out" / "plant_paired.md").read_text()
    again = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0 and again.stdout.count("(resumed)") == 4, again.stdout[-2000:]
    assert all(r["resumed"] for r in json.loads((tmp_path / "out" / "plant_paired.json").read_text())["rows"])
    # a saved cycle dug along another path is not overwritten without --force
    saved = tmp_path / "out" / "cycles" / "gravel" / "seed1" / "fixed_on_deeper" / "cycle2" / "cycle1.json.xz"
    text = lzma.decompress(saved.read_bytes()).decode()
    assert text.count('"planned_path_sha256": "') == 1
    saved.write_bytes(lzma.compress(text.replace('"planned_path_sha256": "', '"planned_path_sha256": "0').encode()))
    refused = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert refused.returncode != 0 and "pass --force" in refused.stderr, refused.stderr[-2000:]
    forced = subprocess.run(command + ["--force"], capture_output=True, text=True, timeout=600)
    assert forced.returncode == 0 and forced.stdout.count("(resumed)") == 3, forced.stdout[-2000:]
