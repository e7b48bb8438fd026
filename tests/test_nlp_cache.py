"""The planner's on-disk NLP cache: same plans with and without it, safe against bad entries."""

from __future__ import annotations

import gc
import os
import weakref

import numpy as np
import pytest

from wheelloader.estimator import Bucket, Loader, Pile, PlanningError
from wheelloader.planner import (
    PlannerOptions,
    TrajectoryOptimizer,
    cautious_options,
    cycle_duration,
    default_start,
    nlp,
    nlp_cache,
)

#: A small NLP (10 intervals) keeps the builds of these tests short.
OPTIONS = PlannerOptions(intervals=10)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A fresh cache directory and no NLP of this process's memory cache."""
    monkeypatch.setenv(nlp_cache.ENV_VAR, str(tmp_path / "nlp"))
    monkeypatch.setattr(nlp, "_CACHE", {})
    return tmp_path / "nlp"


def _plan(options=OPTIONS):
    pile = Pile.trapezoid()
    start = default_start(pile)
    return TrajectoryOptimizer(options=options).solve("gravel", pile, start, cycle_duration(pile, start))


def _entries(directory):
    return sorted(directory.glob("nlp-*.casadi"))


def _same(a, b):
    for name in ("t", "x", "z", "blade_angle", "fill", "vx", "vz", "omega", "tangential", "normal"):
        if hasattr(a, name):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.energy == b.energy and a.objective == b.objective and a.iterations == b.iterations
    assert a.status == b.status


def test_plans_are_bit_identical_built_loaded_and_without_cache(cache, monkeypatch):
    built = _plan()
    assert "built and cached" in nlp_cache.origin(Bucket(), Loader(), OPTIONS)
    assert len(_entries(cache)) == 1
    monkeypatch.setattr(nlp, "_CACHE", {})
    loaded = _plan()
    assert nlp_cache.origin(Bucket(), Loader(), OPTIONS).startswith("loaded from")
    monkeypatch.setenv(nlp_cache.ENV_VAR, "off")
    monkeypatch.setattr(nlp, "_CACHE", {})
    uncached = _plan()
    assert nlp_cache.origin(Bucket(), Loader(), OPTIONS) == "built (cache off)"
    _same(built, loaded)
    _same(built, uncached)
    assert np.isfinite(built.x).all() and built.final_fill > 0.0


@pytest.mark.parametrize("damage", ["truncate", pytest.param("garbage", marks=pytest.mark.slow),
                                    pytest.param("other_key", marks=pytest.mark.slow)])
def test_a_bad_entry_is_rebuilt_not_a_crash(cache, monkeypatch, damage, caplog):
    reference = _plan()
    (entry,) = _entries(cache)
    data = entry.read_bytes()
    if damage == "truncate":
        entry.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        entry.write_bytes(b"x" * 1000 + data[-nlp_cache._TRAILER:])
    else:  # a complete entry whose header names other settings
        monkeypatch.setattr(nlp_cache, "cache_key", lambda *a: "0" * 64)
        monkeypatch.setattr(nlp, "_CACHE", {})
        _plan(PlannerOptions(intervals=10, energy_weight=0.03))  # writes nlp-000... with that key
        monkeypatch.undo()
        monkeypatch.setenv(nlp_cache.ENV_VAR, str(cache))
        other = cache / ("nlp-" + "0" * 40 + ".casadi")
        other.replace(entry)
    monkeypatch.setattr(nlp, "_CACHE", {})
    with caplog.at_level("WARNING"):
        again = _plan()
    assert "unreadable" in caplog.text
    assert "built and cached" in nlp_cache.origin(Bucket(), Loader(), OPTIONS)
    _same(reference, again)
    monkeypatch.setattr(nlp, "_CACHE", {})
    _plan()  # the rewritten entry loads
    assert nlp_cache.origin(Bucket(), Loader(), OPTIONS).startswith("loaded from")


def test_key_follows_the_settings_and_location_follows_the_environment(tmp_path, monkeypatch):
    key = nlp_cache.cache_key(Bucket(), Loader(), OPTIONS)
    assert key == nlp_cache.cache_key(Bucket(), Loader(), PlannerOptions(intervals=10))
    assert key != nlp_cache.cache_key(Bucket(), Loader(), PlannerOptions(intervals=11))
    assert key != nlp_cache.cache_key(Bucket(width=1.1), Loader(), OPTIONS)
    assert key != nlp_cache.cache_key(Bucket(), Loader(), PlannerOptions(intervals=10, max_iter=99))
    monkeypatch.delenv(nlp_cache.ENV_VAR)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert nlp_cache.cache_dir() == tmp_path / "wheelloader" / "nlp"
    monkeypatch.setenv(nlp_cache.ENV_VAR, str(tmp_path / "elsewhere"))
    assert nlp_cache.cache_dir() == tmp_path / "elsewhere"
    for off in ("off", "0", "false", ""):
        monkeypatch.setenv(nlp_cache.ENV_VAR, off)
        assert nlp_cache.cache_dir() is None


def test_an_unwritable_cache_only_costs_time(tmp_path, monkeypatch, caplog):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv(nlp_cache.ENV_VAR, str(blocker / "nlp"))
    monkeypatch.setattr(nlp, "_CACHE", {})
    with caplog.at_level("WARNING"):
        plan = _plan()
    assert "could not write the NLP cache" in caplog.text
    assert nlp_cache.origin(Bucket(), Loader(), OPTIONS) == "built"
    assert np.isfinite(plan.x).all()


def test_old_entries_are_pruned(cache, monkeypatch):
    cache.mkdir(parents=True)
    for i in range(nlp_cache.MAX_ENTRIES + 3):
        old = cache / f"nlp-{i:040d}.casadi"
        old.write_bytes(b"old")

        os.utime(old, (1000.0 + i, 1000.0 + i))
    _plan()
    names = [p.name for p in _entries(cache)]
    assert len(names) == nlp_cache.MAX_ENTRIES
    assert f"nlp-{0:040d}.casadi" not in names  # the least recently used went first


def test_settings_that_do_not_shape_the_nlp_share_it(cache):
    """IPOPT's settings, the bounds and the energy weight share one NLP (one disk entry, one set of derivatives);
    a margin or the transcription does not."""
    variants = [PlannerOptions(intervals=10, max_iter=15), PlannerOptions(intervals=10, energy_weight=0.05),
                PlannerOptions(intervals=10, fill_limit=0.8, lift_headroom=0.5, tolerance=1e-6),
                PlannerOptions(intervals=10, ipopt_warm_start=True, max_wall_time=5.0)]
    for options in variants:
        assert nlp.structural_options(options) == OPTIONS
    assert nlp.structural_options(PlannerOptions(intervals=10, force_margin=0.8)) != OPTIONS
    assert nlp.structural_options(PlannerOptions(intervals=10, rho_margin=0.1)) != OPTIONS
    for options in (OPTIONS, *variants):
        TrajectoryOptimizer(options=options)
    (entry,) = nlp._CACHE.values()
    assert len(entry["solvers"]) == len(variants)  # the energy weight (a parameter) shares the first solver
    assert len(_entries(cache)) == 1
    assert nlp.origin(Bucket(), Loader(), variants[0]).startswith("built and cached")


def test_a_solver_made_from_another_solvers_derivatives_plans_bit_identically(monkeypatch):
    monkeypatch.setenv(nlp_cache.ENV_VAR, "off")
    monkeypatch.setattr(nlp, "_CACHE", {})
    short = PlannerOptions(intervals=10, max_iter=15)
    _plan()  # builds the NLP and its derivatives with the default solver settings
    shared = _plan(short)  # a second solver on the first one's derivatives
    monkeypatch.setattr(nlp, "_CACHE", {})
    alone = _plan(short)  # differentiated on its own
    _same(shared, alone)
    assert shared.iterations == 15 and not shared.success


@pytest.fixture
def one_per_family():
    """The demo's memory rule for this test: one NLP of a margin family in memory."""
    held = nlp.hold_margin_variants(False)
    yield
    nlp.hold_margin_variants(held)


def test_a_margin_variant_takes_the_nlps_place_in_memory_with_the_same_plans(cache, one_per_family):
    """With hold_margin_variants(False) (the demo's rule), the loop's wider-margin re-plan NLP replaces the plan's
    NLP in this process's memory (one NLP of a margin family at a time: ~150 MB each at 40 intervals); the plan's
    NLP is built again at its next solve and plans bit-identically. Another transcription is not a margin
    variant: both stay."""
    opt = TrajectoryOptimizer(options=OPTIONS)
    pile = Pile.trapezoid()
    start = default_start(pile)
    first = opt.solve("gravel", pile, start, cycle_duration(pile, start))
    held = weakref.ref(nlp._CACHE[(Bucket(), Loader(), OPTIONS)])
    wider = cautious_options(OPTIONS)
    TrajectoryOptimizer(options=wider)
    assert list(nlp._CACHE) == [(Bucket(), Loader(), nlp.structural_options(wider))]
    gc.collect()
    assert held() is None  # freed: the optimiser holds no reference to its NLP
    again = opt.solve("gravel", pile, start, cycle_duration(pile, start))  # the same optimiser object
    assert list(nlp._CACHE) == [(Bucket(), Loader(), OPTIONS)]
    _same(first, again)
    TrajectoryOptimizer(options=PlannerOptions(intervals=8))
    assert len(nlp._CACHE) == 2


def test_by_default_margin_variants_stay_in_memory_and_nothing_is_built_twice(cache, monkeypatch):
    """The default rule holds the plan's NLP beside its wider-margin variant: after a re-plan's NLP the plan's
    next solve builds nothing (no nlpsol) and plans as before; the rule is restored as it was set."""
    assert nlp.hold_margin_variants(True) is True  # the default
    opt = TrajectoryOptimizer(options=OPTIONS)
    pile = Pile.trapezoid()
    start = default_start(pile)
    first = opt.solve("gravel", pile, start, cycle_duration(pile, start))
    wider = cautious_options(OPTIONS)
    TrajectoryOptimizer(options=wider)
    assert set(nlp._CACHE) == {(Bucket(), Loader(), OPTIONS), (Bucket(), Loader(), nlp.structural_options(wider))}
    built = []
    real = nlp.ca.nlpsol
    monkeypatch.setattr(nlp.ca, "nlpsol", lambda *a, **k: built.append(a[0]) or real(*a, **k))
    _same(first, opt.solve("gravel", pile, start, cycle_duration(pile, start)))
    assert built == []
    assert nlp.hold_margin_variants(False) is True and nlp.hold_margin_variants(True) is False
    with pytest.raises(PlanningError, match="True or False"):
        nlp.hold_margin_variants(1)


def test_release_drops_the_nlps_and_the_next_solve_builds_them_again(cache):
    opt = TrajectoryOptimizer(options=OPTIONS)
    pile = Pile.trapezoid()
    start = default_start(pile)
    first = opt.solve("gravel", pile, start, cycle_duration(pile, start))
    (entry,) = nlp._CACHE.values()
    (solver, _), = entry["solvers"].values()
    assert not solver.has_function("nlp_grad")  # never evaluated (no lam_p, lam_x, f or g asked after a solve)
    assert nlp.release() == 1 and not nlp._CACHE
    del entry, solver  # nothing holds the NLP now: its memory is freed, and the optimiser builds it again
    _same(first, opt.solve("gravel", pile, start, cycle_duration(pile, start)))
    assert len(nlp._CACHE) == 1
