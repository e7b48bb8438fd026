"""``benchmarks/transfer.py``: the split is by case family, and the shipped manifest is the split it makes."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from benchmark_scripts import load_benchmark

from wheelloader.estimator import CycleLog

ROOT = Path(__file__).resolve().parents[1]


def _split():
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        return load_benchmark("transfer").split(Path("data/mpm"), Path("data/results"))
    finally:
        os.chdir(cwd)


def test_no_test_family_and_no_held_out_soil_or_pile_is_trained_on():
    split = _split()
    train, validation = split["train"], split["validation"]
    assert len(train) >= 150 and len(validation) >= 40
    test = [p for paths in split["test"].values() for p in paths]
    assert set(train).isdisjoint(test) and set(validation).isdisjoint(test) and set(train).isdisjoint(validation)
    # validation is a path family of its own (the end55 loops), never trained on
    assert all("adaptation_mpm_end55" in p for p in validation)
    assert not any("adaptation_mpm_end55" in p for p in train)
    for path in train:  # only the loops' soils, never a held-out soil or pile
        name = Path(path).parts
        assert "gravel" in name or "sand" in name
        assert not any(s in path for s in ("dirt", "modified_sand", "slope25", "data/mpm"))
    assert all(Path(p).is_file() for p in train + validation + test)


def test_no_copy_of_a_test_cycle_is_trained_on_under_another_name():
    # a loop's first fixed cycle on the start pile is data/mpm's path 1 itself: it must be dropped by content
    split = _split()
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        test = {CycleLog.load(p).content_digest() for paths in split["test"].values() for p in paths}
        assert split["dropped_as_test_copies"]  # the shipped loops do hold such copies
        assert not any(CycleLog.load(p).content_digest() in test
                       for p in split["train"] + split["validation"] + split["payload_extra"])
        assert all(CycleLog.load(p).content_digest() in test for p in split["dropped_as_test_copies"])
    finally:
        os.chdir(cwd)


def test_the_payloads_extra_cycles_hold_no_test_family_and_no_held_out_soil_or_pile():
    split = _split()
    extra = split["payload_extra"]
    assert len(extra) >= 40 and all(Path(p).is_file() for p in extra)
    test = [p for paths in split["test"].values() for p in paths]
    assert set(extra).isdisjoint(test + split["train"] + split["validation"])
    assert not any(s in p for p in extra for s in ("dirt", "modified_sand", "slope25", "data/mpm", "end55"))
    # the candidates include the plain fit of the training cycles (the payload before the recipe was chosen)
    module = load_benchmark("transfer")
    assert {"cycles": "train", "samples": "path", "curl": False, "max_kept_ratio": None} in module.PAYLOAD_CANDIDATES


def test_the_band_is_scaled_on_whole_learning_groups_no_model_trains_on():
    from wheelloader.estimator.learned import default_learned_model

    split = _split()
    groups = split["band_validation"]
    assert len(groups) >= 3 and all(len(files) == 3 for files in groups.values())
    files = [f for fs in groups.values() for f in fs]
    assert all(Path(ROOT / f).is_file() and "/learn/" in f for f in files)
    test = [p for paths in split["test"].values() for p in paths]
    assert set(files).isdisjoint(test + split["train"] + split["validation"])
    learned = default_learned_model().manifest["split"]
    trained = {Path(f).name for fs in learned["train"].values() for f in fs}
    assert not trained & {Path(f).name for f in files}
    # whole groups: every cycle of a held-out group (one soil, pile and edge), none of another
    assert {Path(f).name[:7] for f in files}.isdisjoint({Path(f).name[:7] for f in trained})


def test_band_scale_is_the_smallest_reaching_the_level():
    import numpy as np

    module = load_benchmark("transfer")
    rng = np.random.default_rng(0)
    records = [{"ratios": np.abs(rng.normal(size=400)) * s} for s in (0.5, 1.0, 2.0)]
    k = module.band_scale(records, 0.9)
    # the median prediction (ratios |N(0, 1)|) holds 90 % of its samples from its 360th smallest ratio on
    assert k == pytest.approx(float(np.sort(records[1]["ratios"])[359]), rel=1e-6)


def test_band_scale_of_families_weighs_each_family_the_same():
    import numpy as np

    module = load_benchmark("transfer")
    rng = np.random.default_rng(1)
    small = [{"ratios": np.abs(rng.normal(size=400)) * 2.0} for _ in range(3)]
    large = [{"ratios": np.abs(rng.normal(size=400)) * 0.5} for _ in range(30)]
    assert module.band_scale_families([large]) == pytest.approx(module.band_scale(large), rel=1e-12)
    k = module.band_scale_families([small, large])
    coverage = [np.median([np.mean(r["ratios"] <= k) for r in fam]) for fam in (small, large)]
    assert np.mean(coverage) >= 0.9 > np.mean([np.median([np.mean(r["ratios"] <= 0.999 * k) for r in fam])
                                              for fam in (small, large)])
    # pooled, the ten times larger family would decide the scale; as families, the small one pulls it up
    assert k > module.band_scale(small + large)


def test_the_shipped_manifest_is_the_split():
    shipped = json.loads((ROOT / "docs" / "results" / "transfer" / "manifest.json").read_text())
    assert shipped == _split()


def test_the_force_models_benchmark_fits_the_default_payload_to_its_stated_cycles():
    module = load_benchmark("force_models")
    paths = module.payload_cycles(ROOT / "data" / "mpm", ROOT / "data" / "results")
    assert len(paths) == 254
    assert not any(p.name.startswith("dirt") or "slope25" in p.name for p in paths)
