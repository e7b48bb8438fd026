"""The MPM learning-set design (wheelloader.references.mpm.learning_set): seeded, grouped, held-out pile kept out."""

import math

import pytest

from wheelloader.estimator import Bucket
from wheelloader.references.mpm.learning_set import PATHS_PER_GROUP, SLOPES_DEG, design, edge_shape, main


def test_design_is_seeded_and_grouped_by_case_family():
    cases = design(12)
    assert cases == design(12) and cases != design(12, seed=1)
    assert cases[:6] == design(6)  # a prefix of the design is the smaller design
    for g in range(0, 12, PATHS_PER_GROUP):
        group = cases[g:g + PATHS_PER_GROUP]
        assert len({(c.slope_deg, c.edge_height, tuple(sorted(c.soil.items()))) for c in group}) == 1
        assert [c.control[0] for c in group] == sorted(c.control[0] for c in group)  # shallow, middle, deep
    assert {c.slope_deg for c in cases} <= set(SLOPES_DEG) and 25.0 not in SLOPES_DEG
    assert {c.soil_family for c in cases} == {"cohesive", "cohesionless"}
    for c in cases:
        assert (c.soil["cohesion"] > 0) == (c.soil_family == "cohesive")
        assert math.radians(28) <= c.soil["phi"] <= math.radians(46) + 1e-4
        c.soil_params()
        assert c.path().t[-1] == pytest.approx(c.duration, abs=1.0 / 60)  # whole samples at 60 Hz


def test_blunt_edge_adds_a_front_face_and_keeps_the_outline():
    sharp, blunt = edge_shape(Bucket(), 0.0), edge_shape(Bucket(), 0.03)
    assert len(blunt.plates) == len(sharp.plates) + 1
    assert blunt.plates[-1].start == (0.0, -0.03) and blunt.plates[-1].end == (0.0, 0.0)
    assert (blunt.outline == sharp.outline).all()


def test_bad_count_is_one_line_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--count", "0", "--list"])
    assert exc.value.code == 2
    assert "--count must be >= 1" in capsys.readouterr().err
