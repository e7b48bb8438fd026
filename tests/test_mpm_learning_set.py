"""The MPM learning-set design (wheelloader.references.mpm.learning_set): seeded, grouped, held-out pile kept out."""

import json
import math
from dataclasses import asdict
from pathlib import Path

import pytest

from wheelloader.estimator import Bucket
from wheelloader.references.mpm.learning_set import (
    PATHS_PER_GROUP,
    SLOPES_DEG,
    design,
    edge_shape,
    group_part,
    main,
    manifest_split,
    merge,
)

LEARN = Path(__file__).resolve().parents[1] / "data" / "learn"


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


def test_the_shipped_manifest_and_the_folder_agree_both_ways():
    manifest = json.loads((LEARN / "manifest.json").read_text())
    listed = [e["name"] for e in manifest["cycles"]]
    assert listed == sorted(set(listed))  # sorted, each once
    on_disk = {p.name[:-len(".csv.xz")] for p in LEARN.glob("*.csv.xz")}
    sidecars = {p.name[:-len(".json.xz")] for p in LEARN.glob("*.json.xz")}
    assert set(listed) == on_disk == sidecars  # every file listed, every entry on disk
    assert all(e["csv"] == f"{e['name']}.csv.xz" for e in manifest["cycles"])
    drawn = {c.name: json.loads(json.dumps(asdict(c))) for c in design(len(listed) + 3 * PATHS_PER_GROUP)}
    assert all(e["case"] == drawn[e["name"]] for e in manifest["cycles"])  # the seeded design's cases
    assert manifest["split"] == manifest_split(listed)
    assert sum(b["count"] for b in manifest["batches"]) == len(listed)


def test_the_split_is_fixed_by_the_group_number():
    assert [group_part(f"learn{g:02d}") for g in range(6)] == ["train", "validation", "train", "train", "train",
                                                               "validation"]
    assert group_part("learn37b") == "validation" and group_part("learn36a") == "train"
    # a missing group moves no other group across the split
    assert manifest_split(["learn00a", "learn02b", "learn05a"])["validation"] == ["learn05"]


def test_the_learned_weights_split_is_the_manifests():
    from wheelloader.estimator.learned import default_learned_model

    shipped = default_learned_model().manifest["split"]
    manifest = json.loads((LEARN / "manifest.json").read_text())["split"]
    assert {g.split("/")[1] for g in shipped["validation_learn"]} <= set(manifest["validation"])
    assert {g.split("/")[1] for g in shipped["train_learn"]} <= set(manifest["train"])


def _learning_folder(folder: Path, names: list[str], payload: bytes = b"x") -> Path:
    folder.mkdir()
    cases = {c.name: c for c in design(12)}
    entries = [{"name": n, "csv": f"{n}.csv.xz", "case": asdict(cases[n])} for n in names]
    for n in names:
        (folder / f"{n}.csv.xz").write_bytes(payload + n.encode())
        (folder / f"{n}.json.xz").write_bytes(b"{}")
    (folder / "manifest.json").write_text(json.dumps({"format": "wheelloader.mpm-learning-set", "version": 1,
                                                      "cycles": entries, "generated_with": {"git": n}}))
    return folder


def test_merge_copies_new_cycles_and_never_overwrites(tmp_path):
    out = _learning_folder(tmp_path / "out", ["learn00a", "learn00b"])
    src = _learning_folder(tmp_path / "src", ["learn00b", "learn01a", "learn01b"])
    assert merge(out, [src]) == ["learn01a", "learn01b"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert [e["name"] for e in manifest["cycles"]] == ["learn00a", "learn00b", "learn01a", "learn01b"]
    assert manifest["split"]["validation"] == ["learn01"] and manifest["batches"][0]["count"] == 2
    assert (out / "learn01a.csv.xz").read_bytes() == b"xlearn01a"
    assert merge(out, [src]) == []  # the same files again: nothing to do, no second batch
    assert len(json.loads((out / "manifest.json").read_text())["batches"]) == 1
    other = _learning_folder(tmp_path / "other", ["learn00a"], payload=b"y")
    with pytest.raises(ValueError, match="other contents"):
        merge(out, [other])
    assert (out / "learn00a.csv.xz").read_bytes() == b"xlearn00a"


def test_merge_of_a_folder_without_a_manifest_is_one_line_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--out", str(tmp_path / "out"), "--merge", str(tmp_path)])
    assert exc.value.code == 2
    assert capsys.readouterr().err.startswith("wheelloader: error:")
