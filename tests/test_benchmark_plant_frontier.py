"""``benchmarks/plant_frontier.py`` (#33: the plant's own energy-vs-kept frontier): the design, the path family,
the frontier and the summary on known answers; the whole script in the FEE env plant (a stub of the MPM plant)."""

from __future__ import annotations

import json

import pytest
from benchmark_scripts import load_benchmark

from wheelloader.estimator import preset
from wheelloader.estimator.force_model import GRAVITY
from wheelloader.estimator.paths import default_path
from wheelloader.saved_loops import path_digest


@pytest.fixture(scope="module")
def pf():
    return load_benchmark("plant_frontier")


def test_design_is_seeded_inside_its_box_and_a_larger_count_keeps_the_smaller_as_prefix(pf):
    small, large = pf.design(5), pf.design(12)
    assert large[:5] == small
    assert pf.design(5, seed=1) != small
    assert pf.design(0) == []
    for point in large:
        assert list(point) == list(pf.BOUNDS)
        for key, (low, high) in pf.BOUNDS.items():
            assert low <= point[key] <= high
    for key, value in pf.FIXED.items():  # the fixed path lies inside the box the design spans
        low, high = pf.BOUNDS[key]
        assert low <= value <= high


def test_the_local_design_is_the_same_points_in_a_box_shrunk_around_the_fixed_path(pf):
    wide, local = pf.design(6), pf.design(6, scale=pf.LOCAL_SCALE)
    for w, q in zip(wide, local, strict=True):
        for key in pf.BOUNDS:
            assert q[key] - pf.FIXED[key] == pytest.approx(pf.LOCAL_SCALE * (w[key] - pf.FIXED[key]), abs=2e-4)


def test_the_fixed_parameters_give_the_fixed_path_and_variants_keep_within_the_loaders_limits(pf):
    path, duration = pf.variant_path(pf.FIXED)
    assert duration == pf.FIXED["duration_s"]
    assert path_digest(path) == path_digest(default_path())
    stretched = 0
    for params in pf.design(16):
        path, duration = pf.variant_path(params)
        assert duration >= params["duration_s"]
        stretched += duration > params["duration_s"]
        assert all(v <= 1.0 for v in pf.limit_ratios(path).values()), params
        assert path.z[-1] == pytest.approx(params["end_z"])
    assert stretched > 0  # the box holds curls too fast for the loader: they are slowed down, not dropped


def test_pareto_front_known_answer(pf):
    # (energy per m^3, fill): 1 dominates 3; 0, 1 and 2 trade off; 4 equals 1 (neither dominates the other)
    points = [(10.0, 0.08), (12.0, 0.10), (15.0, 0.12), (13.0, 0.09), (12.0, 0.10)]
    assert pf.pareto(points) == [0, 1, 4, 2]
    assert pf.pareto([]) == []


def _row(name, lifted, fill, pile="gravel", above=False, kind="variant"):
    return {"pile": pile, "kind": kind, "name": name, "lifted_per_m3_kJ": lifted, "fill_m3": fill,
            "kept_fill": fill / 0.2, "above_limits": above}


def test_summary_known_answer(pf):
    rows = [_row("fixed", 40.0, 0.100), _row("v01", 33.0, 0.101), _row("v02", 30.0, 0.099),
            _row("v03", 20.0, 0.120, above=True), _row("v04", 36.0, 0.110), _row("ours", 35.0, 0.104, kind="reference"),
            _row("p01", 34.0, 0.102), _row("fixed", 50.0, 0.1, pile="sand"), _row("v01", 49.0, 0.09, pile="sand")]
    s = pf.summarise(rows)
    g = s["gravel"]
    assert g["best_name"] == "v01" and g["best_ratio_kept_ge_fixed"] == pytest.approx(33.0 / 40.0)
    assert g["reach_085"] == 2 and g["kept_ge_fixed"] == 4  # v01, p01, v04 and ours; v03 is above the limits
    assert g["variants"] == 6 and g["above_limits"] == 1
    assert g["frontier"] == ["v02", "v01", "p01", "ours", "v04"]
    assert g["least_ratio_any_fill"] == pytest.approx(30.0 / 40.0)
    # the family's frontier (v02 at 0.099 m^3, v01 at 0.101, v04; v01 dominates fixed): halfway between v02 and v01
    assert g["family_frontier_ratio_at_fixed_fill"] == pytest.approx(31.5 / 40.0)
    assert s["sand"]["family_frontier_ratio_at_fixed_fill"] == pytest.approx(1.0)  # the fixed path is its end
    bezier, planned = g["families"]["Bézier (the fixed path's)"], g["families"]["the planned path varied"]
    assert (bezier["best_name"], bezier["count"], bezier["kept_ge_fixed"]) == ("v01", 5, 2)
    assert bezier["frontier_ratio_at_fixed_fill"] == pytest.approx(31.5 / 40.0)
    assert (planned["best_name"], planned["reach_085"]) == ("p01", 1)
    assert g["families"]["the loops' own plans"]["best_ratio"] == pytest.approx(35.0 / 40.0)
    assert s["sand"]["best_name"] is None and s["sand"]["reach_085"] == 0


def test_runs_end_to_end_in_the_fee_env_plant_and_resumes(pf, tmp_path, capsys):
    out = tmp_path / "frontier"
    argv = ["--plant", "fee-env", "--count", "2", "--piles", "sand", "--out", str(out)]
    assert pf.main(argv) == 0
    result = json.loads((out / "plant_frontier.json").read_text())
    assert [r["name"] for r in result["rows"]] == ["fixed", "v01", "v02"]
    assert not any(r["resumed"] for r in result["rows"])
    assert (out / "plant_frontier.png").stat().st_size > 0
    assert (out / "progress.txt").read_text().count("\n") == 3
    fixed = result["rows"][0]
    assert result["summary"]["sand"]["fixed_lifted_per_m3_kJ"] == fixed["lifted_per_m3_kJ"]
    # the lift: the kept load from the path's end to 1.20 m, with the plant's work
    lift = preset("sand").gamma * GRAVITY * fixed["fill_m3"] * (result["z_ref_m"] - fixed["z_end_m"])
    assert result["z_ref_m"] == pytest.approx(1.20)
    assert fixed["lifted_J"] == pytest.approx(fixed["energy_J"] + lift)
    assert fixed["lifted_per_m3_kJ"] == pytest.approx(fixed["lifted_J"] / fixed["fill_m3"] / 1e3)
    assert pf.main(argv[:3] + ["3"] + argv[4:]) == 0  # a larger design digs only the new point
    again = json.loads((out / "plant_frontier.json").read_text())
    assert [r["resumed"] for r in again["rows"]] == [True, True, True, False]
    table, digs = (out / "plant_frontier.md").read_text(), (out / "plant_frontier_digs.md").read_text()
    assert "| sand | fixed |" in digs and "v03" in digs
    assert "| sand |" in table and "Bézier" in table
    assert pf.main(["--report", "--out", str(out)]) == 0
    assert (out / "plant_frontier.md").read_text() == table
    assert (out / "plant_frontier_digs.md").read_text() == digs
    # another pile into the same OUT joins the first pile's rows; --local adds points of the shrunk box
    assert pf.main(["--plant", "fee-env", "--count", "0", "--local", "1", "--piles", "gravel", "--out", str(out)]) == 0
    both = json.loads((out / "plant_frontier.json").read_text())
    assert [(r["pile"], r["name"]) for r in both["rows"]][-2:] == [("gravel", "fixed"), ("gravel", "l01")]
    assert len([r for r in both["rows"] if r["pile"] == "sand"]) == 4
    assert [i["labels"] for i in both["invocations"]] == [["sand"], ["gravel"]]
    assert set(both["summary"]) == {"sand", "gravel"}


@pytest.mark.parametrize("argv", [["--count", "-1"], ["--piles", "clay"], ["--piles", "sand:/nonexistent:3"],
                                  ["--report", "--out", "/nonexistent/frontier"]])
def test_bad_input_one_line_exit_2(pf, argv, capsys):
    with pytest.raises(SystemExit) as exc:
        pf.main(["--plant", "fee-env", *argv])
    assert exc.value.code == 2
    assert capsys.readouterr().err.startswith("wheelloader: error:")


def test_the_planned_family_varies_the_loops_planned_path(pf):
    from pathlib import Path

    from wheelloader.saved_loops import load_saved_cycle

    saved = Path(__file__).resolve().parents[1] / "data/results/loop_mpm_learned/cycles/loops/gravel/seed0/ours"
    log = load_saved_cycle(saved, 1, check=False)
    if log is None:
        pytest.skip("the learned loop's saved cycles are not in this checkout")
    base, pile = log.path, log.pile
    same, duration = pf.planned_variant(base, pile, {"depth_scale": 1.0, "angle_offset_deg": 0.0, "x_stretch": 1.0})
    assert duration == pytest.approx(base.t[-1] - base.t[0])
    assert same.x == pytest.approx(base.x, abs=1e-12) and same.z == pytest.approx(base.z, abs=1e-12)
    deeper, _ = pf.planned_variant(base, pile, {"depth_scale": 1.2, "angle_offset_deg": 5.0, "x_stretch": 1.0})
    depth = pile.surface_height(base.x) - base.z
    below = depth > 0
    assert (pile.surface_height(deeper.x) - deeper.z)[below] == pytest.approx(1.2 * depth[below])
    assert deeper.blade_angle[0] == pytest.approx(base.blade_angle[0] + 5.0 * 3.141592653589793 / 180)
    assert deeper.blade_angle[-1] == pytest.approx(base.blade_angle[-1])  # the offset fades out before the end
    for params in pf.planned_design(8):
        variant, _ = pf.planned_variant(base, pile, params)
        caps = {k: max(1.0, v) for k, v in pf.limit_ratios(base).items()}
        assert all(v <= caps[k] + 1e-9 for k, v in pf.limit_ratios(variant).items())


def test_a_carved_piles_references_come_from_its_own_loop_only(pf):
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "data/results"
    learned, v3 = root / "loop_mpm_learned/cycles", root / "loop_mpm_v3/cycles"
    if not (learned / "loops/gravel/seed0/ours").is_dir() or not (v3 / "loops").is_dir():
        pytest.skip("the saved loops are not in this checkout")
    refs = [("learned", str(learned)), ("v3", str(v3))]
    carved = pf.references(f"gravel:{learned}:3", "carved", refs, 1.2)
    assert [r["name"] for r in carved] == ["ours (learned)", "fixed (learned, saved)"]
    fresh = pf.references("gravel", "gravel", refs, 1.2)
    assert [r["name"] for r in fresh] == ["ours (learned)", "fixed (learned, saved)", "ours (v3)", "fixed (v3, saved)"]
