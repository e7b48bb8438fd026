"""The MPM reference-set generator's bookkeeping (no Taichi: a stand-in plant)."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from wheelloader.estimator import CycleLog, Pile
from wheelloader.references.mpm import generate


class FakePlant:
    """Digs instantly: forces from the path, a pile lowered by 1 cm."""

    name = "mpm"

    def __init__(self):
        self.settings = SimpleNamespace(resolution=0.02)
        self.calls = []

    def dig(self, path, pile, soil, *, seed=0):
        self.calls.append((path.name, soil, float(pile.heights.sum())))
        n = len(path)
        return CycleLog(path, np.full(n, 100.0), np.full(n, 50.0), pile, fill_volume=np.linspace(0, 0.1, n),
                        pile_after=pile.with_heights(pile.heights - 0.01),
                        metadata={"seed": seed, "resolution": 0.02, "wall_s": 1.0, "particles": 10})


def test_case_list_covers_the_brief():
    names = [c.name for c in generate.cases()]
    assert len(names) == len(set(names)) == 18
    for soil in ("gravel", "sand", "dirt", "modified_sand"):
        for k in range(1, 5):
            assert f"{soil}_path{k}" in names
    dual = next(c for c in generate.cases() if c.name == "gravel_dual")
    assert dual.stems() == ["gravel_dual_cycle1", "gravel_dual_cycle2"]
    slope = next(c for c in generate.cases() if c.name == "gravel_slope25_path1")
    assert slope.slope == pytest.approx(math.radians(25.0))
    with pytest.raises(ValueError, match="path key"):
        generate.path_by_key("path9")


def test_generation_writes_resumes_and_chains_the_dual_cycle(tmp_path):
    plant = FakePlant()
    cases = {c.name: c for c in generate.cases()}
    generate.generate_case(cases["gravel_path1"], tmp_path, plant, log=lambda m: None)
    assert generate.done(tmp_path, cases["gravel_path1"])
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    entry = manifest["cycles"][0]
    assert entry["name"] == "gravel_path1"
    assert entry["command"] == "python -m wheelloader.references.mpm.generate --out data/mpm --only gravel_path1"
    # the dual pair: cycle 1 is copied from gravel_path1, cycle 2 dug on the surface cycle 1 left
    generate.generate_case(cases["gravel_dual"], tmp_path, plant, log=lambda m: None)
    assert len(plant.calls) == 2
    assert plant.calls[1][0] == "dual cycle 2"
    start = Pile.trapezoid()
    assert plant.calls[1][2] == pytest.approx(float((start.heights - 0.01).sum()))
    second = CycleLog.load(tmp_path / "gravel_dual_cycle2.csv")
    assert second.pile.heights == pytest.approx(start.heights - 0.01)
    # resuming skips what exists
    generate.generate_case(cases["gravel_dual"], tmp_path, plant, log=lambda m: None)
    assert len(plant.calls) == 2
    names = [e["name"] for e in json.loads((tmp_path / "manifest.json").read_text())["cycles"]]
    assert names == ["gravel_path1", "gravel_dual_cycle1", "gravel_dual_cycle2"]
