"""The plane-strain MPM reference plant: a tiny scene, behaviour only (seconds, including Taichi's compile)."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from wheelloader.estimator import Bucket, CycleLog, Pile, bezier_path, preset
from wheelloader.references import Plant
from wheelloader.references.mpm import ContinuumSoil, MPMPlant, MPMSettings, SceneSettings, jaky_poisson_ratio

REQUIRE = os.environ.get("WHEELLOADER_REQUIRE_MPM") == "1"


def _need_taichi() -> None:
    try:
        import taichi  # noqa: F401
    except ImportError:
        if REQUIRE:
            pytest.fail("WHEELLOADER_REQUIRE_MPM=1 but taichi is not installed (pip install \"wheelloader[mpm]\")")
        pytest.skip('taichi not installed: pip install "wheelloader[mpm]" (set WHEELLOADER_REQUIRE_MPM=1 to fail)')


# ------------------------------------------------------------------ no Taichi needed
def test_package_imports_without_taichi():
    code = ("import sys, wheelloader.references, wheelloader.references.mpm as m; "
            "m.MPMPlant(0.05); print('taichi' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_missing_taichi_names_the_extra(monkeypatch):
    from wheelloader.references.mpm import _backend

    monkeypatch.setitem(_backend._STATE, "ti", None)
    monkeypatch.setitem(sys.modules, "taichi", None)
    with pytest.raises(_backend.MPMUnavailableError, match=r'pip install "wheelloader\[mpm\]"'):
        _backend.taichi_module(1)


def test_continuum_soil_from_presets():
    dirt = preset("dirt")
    soil = ContinuumSoil.from_soil("dirt")
    assert soil.density == dirt.gamma and soil.cohesion == dirt.cohesion and soil.adhesion == dirt.adhesion
    assert soil.friction_angle == dirt.phi and soil.wall_friction_angle == dirt.delta
    # the Poisson ratio makes the elastic at-rest ratio equal to Jaky's 1 - sin(phi)
    assert soil.at_rest_ratio == pytest.approx(1.0 - math.sin(dirt.phi))
    assert 0.0 < jaky_poisson_ratio(0.0) < 0.5
    assert ContinuumSoil.from_soil(dirt, poisson_ratio=0.25).poisson_ratio == 0.25


@pytest.mark.parametrize("changes, name", [
    ({"density": 0.0}, "density"), ({"friction_angle": 1.7}, "radians"), ({"cohesion": -1.0}, "cohesion"),
    ({"adhesion": -1.0}, "adhesion"), ({"poisson_ratio": 0.5}, "poisson_ratio"),
    ({"youngs_modulus": float("nan")}, "youngs_modulus"), ({"friction_angle": 0.0}, "strength"),
])
def test_continuum_soil_rejects_bad_values(changes, name):
    values = {"density": 1500.0, "friction_angle": 0.6} | changes
    with pytest.raises(ValueError, match=name):
        ContinuumSoil(**values)


@pytest.mark.parametrize("kwargs, name", [
    ({"resolution": 0.0}, "resolution"), ({"threads": 0}, "threads"), ({"settle_time": -1.0}, "settle_time"),
    ({"colour": 1}, "colour"), ({"backend": "tpu"}, "backend"), ({"legacy": 1}, "legacy"),
    ({"settle_cache": "yes"}, "settle_cache"), ({"elastic_f": "qr"}, "elastic_f"),
    ({"elastic_f": "svd", "legacy": True}, "elastic_f"),
])
def test_plant_rejects_bad_settings(kwargs, name):
    with pytest.raises(ValueError, match=name):
        MPMPlant(**({"resolution": 0.02} | kwargs))


def test_scene_settings_validation():
    with pytest.raises(ValueError, match="bed_depth"):
        SceneSettings(bed_depth=0.0)
    with pytest.raises(ValueError, match="jitter"):
        SceneSettings(jitter=0.5)
    assert MPMSettings().to_dict()["scene"]["bed_depth"] == SceneSettings().bed_depth


def test_scene_perturbations_reorder_or_move_by_one_unit_in_the_last_place():
    from wheelloader.references.mpm.scene import perturb_particles

    rng = np.random.default_rng(3)
    pts, depth = rng.uniform(0.1, 5.0, (500, 2)), rng.uniform(0.0, 1.0, 500)
    same = perturb_particles(pts, depth)
    np.testing.assert_array_equal(same[0], pts)
    np.testing.assert_array_equal(same[1], depth)
    moved, moved_depth = perturb_particles(pts, depth, order_seed=4)
    assert not np.array_equal(moved, pts)
    rows = np.column_stack([pts, depth])
    rows_moved = np.column_stack([moved, moved_depth])  # each particle keeps its position and depth
    np.testing.assert_array_equal(rows[np.lexsort(rows.T)], rows_moved[np.lexsort(rows_moved.T)])
    jittered, jittered_depth = perturb_particles(pts, depth, ulp_seed=5)
    units = jittered.astype(np.float32).view(np.int32).astype(int) - pts.astype(np.float32).view(np.int32)
    assert np.all(np.abs(units) <= 1) and np.any(units == 1) and np.any(units == -1) and np.any(units == 0)
    np.testing.assert_array_equal(jittered_depth, depth)
    np.testing.assert_array_equal(perturb_particles(pts, depth, 4, 5)[0], perturb_particles(pts, depth, 4, 5)[0])


def test_perturbation_and_elastic_f_settings():
    plain = MPMSettings().to_dict()
    assert set(plain["scene"]) == {"bed_depth", "wall_margin", "front_margin", "top_margin", "jitter"}
    assert "elastic_f" not in plain  # logs dug without them compare equal to those dug before they existed
    changed = MPMSettings(scene=SceneSettings(order_seed=2, ulp_seed=0), elastic_f="svd").to_dict()
    assert changed["scene"]["order_seed"] == 2 and changed["scene"]["ulp_seed"] == 0
    assert changed["elastic_f"] == "svd"
    for bad in ({"order_seed": -1}, {"ulp_seed": 1.5}, {"order_seed": True}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            SceneSettings(**bad)


def test_plant_satisfies_the_protocol():
    assert isinstance(MPMPlant(), Plant)
    assert MPMPlant.name == "mpm"


# ------------------------------------------------------------------ the tiny scene
TINY_BUCKET = Bucket(floor_length=0.15, capacity=0.01)
TINY_PILE = Pile.trapezoid(height=0.25, top_length=0.3, ground_before=0.2)


def tiny_path(dz: float = 0.0):
    """A 1.2 s Bezier scoop into the tiny pile (30 Hz); ``dz`` [m] lowers its control point (a deeper cut).

    It starts more than one contact band (dx = 0.03 m) above the bed: the tool's contact reaches
    ``contact_band * dx`` beyond its plates.
    """
    return bezier_path((-0.03, 0.05), (0.30, 0.03 - dz), (0.38, 0.30), duration=1.2, rate=30.0,
                       angle_start=math.radians(-5.0), angle_end=math.radians(40.0), curl_from=0.5, name="tiny")


def tiny_plant(**settings) -> MPMPlant:
    return MPMPlant(0.03, bucket=TINY_BUCKET, settle_time=0.1,
                    **({"settle_cache": False, "threads": 1, "scene": SceneSettings(bed_depth=0.1, wall_margin=0.2)}
                       | settings))


@pytest.fixture(scope="module")
def digs():
    _need_taichi()
    plant = tiny_plant()
    return {
        "base": plant.dig(tiny_path(), TINY_PILE, "sand", seed=0),
        "again": plant.dig(tiny_path(), TINY_PILE, "sand", seed=0),
        "seed1": plant.dig(tiny_path(), TINY_PILE, "sand", seed=1),
        "deeper": plant.dig(tiny_path(0.04), TINY_PILE, "sand", seed=0),
    }


def test_tiny_dig_gives_finite_forces_in_the_blade_frame(digs):
    log = digs["base"]
    assert np.all(np.isfinite(log.tangential)) and np.all(np.isfinite(log.normal))
    t = log.path.t
    digging = (t > 0.3) & (t < 0.8)
    # penetration resists the motion along the floor (F_T > 0) and the soil above the floor presses it down
    assert np.mean(log.tangential[digging]) > 0.0
    assert np.mean(log.normal[digging]) > 0.0
    # before the tip reaches the toe there is (almost) nothing to push
    assert abs(log.tangential[0]) < 0.1 * np.max(log.tangential)
    assert np.max(log.resultant) < 1e4


def test_tiny_dig_fills_the_bucket_and_carves_the_pile(digs):
    log = digs["base"]
    assert log.fill_volume[0] == 0.0
    assert log.fill_volume[-1] > 0.3 * TINY_BUCKET.capacity
    assert log.pile == TINY_PILE
    assert log.pile_after is not None
    assert TINY_PILE.area() - log.pile_after.area() > 0.5 * log.fill_volume[-1]
    # below the cut the pile is lower, far behind it unchanged
    x_cut = 0.2
    assert log.pile_after.surface_height(x_cut) < TINY_PILE.surface_height(x_cut) - 0.02
    assert log.pile_after.surface_height(2.0) == TINY_PILE.surface_height(2.0)


def test_tiny_dig_conserves_mass(digs):
    balance = digs["base"].metadata["mass_balance"]
    # soil that left the resting pile = soil in the bucket, on it or in flight
    assert balance["net_area_removed"] == pytest.approx(balance["detached_area_end"], rel=1e-6)
    assert 0.0 < balance["fill_area_end"] <= balance["detached_area_end"] + 1e-12
    log = digs["base"]
    # the carved Pile carries the same area change (its grid is finer than the columns: interpolation)
    assert TINY_PILE.area() - log.pile_after.area() == pytest.approx(balance["net_area_removed"], rel=0.1)


def test_tiny_dig_is_deterministic_for_a_seed(digs):
    a, b = digs["base"], digs["again"]
    np.testing.assert_array_equal(a.tangential, b.tangential)
    np.testing.assert_array_equal(a.normal, b.normal)
    np.testing.assert_array_equal(a.fill_volume, b.fill_volume)
    c = digs["seed1"]
    assert not np.array_equal(a.tangential, c.tangential)
    # another packing jitter changes the mean resultant only a little
    assert np.mean(c.resultant) == pytest.approx(np.mean(a.resultant), rel=0.25)


def test_force_grows_with_depth(digs):
    base, deeper = digs["base"], digs["deeper"]
    assert np.mean(deeper.resultant) > 1.2 * np.mean(base.resultant)


def test_cyclelog_round_trips(digs, tmp_path):
    log = digs["base"]
    target = log.save(tmp_path / "tiny.csv")
    back = CycleLog.load(target)
    np.testing.assert_array_equal(back.tangential, log.tangential)
    np.testing.assert_array_equal(back.normal, log.normal)
    np.testing.assert_array_equal(back.fill_volume, log.fill_volume)
    assert back.bucket == TINY_BUCKET
    assert back.metadata["plant"] == "mpm"
    for key in ("resolution", "youngs_modulus", "contact_band", "seed", "particles", "wall_s"):
        assert key in back.metadata
    np.testing.assert_allclose(back.pile_after.heights, log.pile_after.heights)


def test_observer_sees_every_sample():
    _need_taichi()
    seen = []
    path = tiny_path()
    log = tiny_plant().dig(path, TINY_PILE, "gravel", seed=3, observer=lambda t, pos: seen.append((t, pos.shape)))
    assert [t for t, _ in seen] == pytest.approx(list(path.t))
    assert all(shape == (log.metadata["particles"], 2) for _, shape in seen)


def test_struck_capacity_is_the_fill_outline():
    """The default bucket's fill outline (tip, floor 0.45 m back, back plate 0.45 m up, top plate 0.15 m, strike
    line to the tip) holds 0.45 x 0.45 - 0.3 x 0.45 / 2 = 0.135 m^2 per metre (README of the MPM reference)."""
    plant = MPMPlant()
    outline = plant.shape.outline
    x, z = outline[:, 0], outline[:, 1]
    by_hand = 0.5 * abs(sum(x[i] * z[(i + 1) % len(x)] - x[(i + 1) % len(x)] * z[i] for i in range(len(x))))
    assert plant.struck_capacity == pytest.approx(by_hand * plant.bucket.width)
    assert plant.struck_capacity == pytest.approx(0.135, abs=1e-9)
    assert MPMPlant(bucket=Bucket(width=0.5)).struck_capacity == pytest.approx(0.0675, abs=1e-9)


# ------------------------------------------------------------------ the kernels and the settle cache
def _filtered_resultant(log: CycleLog) -> np.ndarray:
    from wheelloader.references.filtering import smooth

    rate = 1.0 / float(np.median(np.diff(log.path.t)))
    return np.hypot(smooth(log.tangential, rate), smooth(log.normal, rate))


def _relative_rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.mean(np.abs(b)))


def test_new_kernels_match_the_legacy_ones_on_the_tiny_scene(digs):
    """The lanes, the stress kept from the return mapping and the tool's box change only the rounding: the
    filtered F_R stays within 1 % of the old kernels' (the issue's tolerance), for one lane and for two."""
    old = tiny_plant(legacy=True).dig(tiny_path(), TINY_PILE, "sand", seed=0)
    assert old.metadata["kernels"] == "legacy" and digs["base"].metadata["kernels"] == "lanes"
    two = tiny_plant(threads=2).dig(tiny_path(), TINY_PILE, "sand", seed=0)
    reference = _filtered_resultant(old)
    for log in (digs["base"], two):
        assert not np.array_equal(log.tangential, old.tangential)  # other kernels indeed ran
        assert _relative_rmse(_filtered_resultant(log), reference) < 0.01
        assert log.fill_volume[-1] == pytest.approx(old.fill_volume[-1], rel=0.02)
    # two lanes are deterministic too (the lanes' grids are added in lane order, whatever the threads)
    again = tiny_plant(threads=2).dig(tiny_path(), TINY_PILE, "sand", seed=0)
    np.testing.assert_array_equal(again.tangential, two.tangential)
    np.testing.assert_array_equal(again.normal, two.normal)


def test_last_bit_perturbations_and_the_svd_update_change_the_forces_by_rounding_only(digs):
    """Another particle order, a one-ulp move of the particles and the old kernels' SVD rebuild of F change the
    tiny dig's forces (other rounding) but not its physics: filtered F_R within 1 %, the same fill."""
    base = digs["base"]
    reference = _filtered_resultant(base)
    scene = {"bed_depth": 0.1, "wall_margin": 0.2}
    for settings in ({"scene": SceneSettings(**scene, order_seed=1)}, {"scene": SceneSettings(**scene, ulp_seed=1)},
                     {"elastic_f": "svd"}):
        log = tiny_plant(**settings).dig(tiny_path(), TINY_PILE, "sand", seed=0)
        assert not np.array_equal(log.tangential, base.tangential), settings
        assert _relative_rmse(_filtered_resultant(log), reference) < 0.01, settings
        assert log.fill_volume[-1] == pytest.approx(base.fill_volume[-1], rel=0.02), settings


def test_settle_cache_hit_gives_bit_identical_forces(digs, tmp_path):
    plant = tiny_plant(settle_cache=True, cache_dir=tmp_path)
    first = plant.dig(tiny_path(), TINY_PILE, "sand", seed=0)
    assert first.metadata["settle_cache"] == "miss"
    assert len(list(tmp_path.glob("settled-*.npz"))) == 1
    second = plant.dig(tiny_path(), TINY_PILE, "sand", seed=0)
    assert second.metadata["settle_cache"] == "hit"
    uncached = digs["base"]
    assert uncached.metadata["settle_cache"] == "off"
    for log in (first, second):
        np.testing.assert_array_equal(log.tangential, uncached.tangential)
        np.testing.assert_array_equal(log.normal, uncached.normal)
        np.testing.assert_array_equal(log.fill_volume, uncached.fill_volume)
        np.testing.assert_array_equal(log.pile_after.heights, uncached.pile_after.heights)
        for key in ("steps", "guard_corrections", "guard_impulse_share", "mass_balance"):
            assert log.metadata[key] == uncached.metadata[key]
    # another scene (seed) misses
    assert plant.dig(tiny_path(), TINY_PILE, "sand", seed=1).metadata["settle_cache"] == "miss"
    assert len(list(tmp_path.glob("settled-*.npz"))) == 2


def test_settle_cache_refuses_a_foreign_state(tmp_path):
    from wheelloader.references.mpm.settle_cache import SettleCache, default_cache_dir, settle_digest

    cache = SettleCache(tmp_path, max_entries=2)
    digests = [settle_digest({"a": np.arange(3.0) + k}, {"k": k}) for k in range(3)]
    assert len(set(digests)) == 3
    assert cache.load(digests[0]) is None
    for k, digest in enumerate(digests):
        cache.save(digest, {"x": np.full(2, float(k))})
    assert len(list(tmp_path.glob("settled-*.npz"))) == 2  # the oldest was pruned
    np.testing.assert_array_equal(cache.load(digests[2])["x"], [2.0, 2.0])
    # a file whose stored digest differs (a prefix collision) is not taken
    (tmp_path / f"settled-{digests[2][:32]}.npz").rename(tmp_path / f"settled-{'0' * 32}.npz")
    assert cache.load("0" * 64) is None
    assert "wheelloader" in str(default_cache_dir()) or "WHEELLOADER_MPM_CACHE" in os.environ


def test_alike_particles_fall_alike_and_as_free_fall_says(digs):
    """Three particles alike (the same place within their cells) and far apart in one lane fall alike, each moved
    once per step, as free fall says (a kernel that skipped or repeated a particle of a lane would fail here)."""
    from wheelloader.references.mpm.solver import Domain, MPMSolver

    dx = 0.03
    start = np.array([[0.3 + 10 * dx * k + 0.25 * dx, 1.0 + 0.25 * dx] for k in range(3)])
    with MPMSolver(ContinuumSoil(1600.0, math.radians(30.0)), Domain(0.0, 0.0, 1.5, 1.5), dx, start) as solver:
        solver.advance(0.1)
        end = solver.positions()
    np.testing.assert_allclose(end[:, 1], end[0, 1], rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(end[:, 0], start[:, 0], rtol=0.0, atol=1e-6)
    assert start[0, 1] - end[0, 1] == pytest.approx(0.5 * 9.81 * 0.1**2, rel=0.02)


def test_atomic_kernels_agree_with_the_lanes_at_the_start_of_a_dig():
    """The GPU kernels (atomic scatter, here on the CPU) and the CPU lanes give the same first 0.2 s of the tiny
    dig up to rounding: the same settled soil and tool impulse within 1e-3."""
    _need_taichi()
    from wheelloader.references.mpm.scene import bucket_scene
    from wheelloader.references.mpm.solver import MPMSolver
    from wheelloader.references.mpm.tool import Trajectory

    plant = tiny_plant()
    traj = Trajectory.from_path(tiny_path())
    scene = bucket_scene(TINY_PILE, traj, plant.shape, 0.03, 0, plant.settings.scene)
    soil = plant.continuum("sand")
    out = {}
    for scatter in ("lanes", "atomic"):
        with MPMSolver(soil, scene.domain, 0.03, scene.particles, tool=plant.shape, scatter=scatter) as solver:
            assert solver.kernels == scatter
            solver.set_geostatic_stress(scene.overburden)
            solver.time = -0.1
            solver.advance(0.0, traj, damping=20.0)
            impulse = solver.advance(0.5, traj)
            out[scatter] = (solver.positions(), impulse)
    assert np.max(np.abs(out["lanes"][0] - out["atomic"][0])) < 1e-3 * 0.03
    np.testing.assert_allclose(out["atomic"][1], out["lanes"][1], rtol=1e-3, atol=1e-3 * np.abs(out["lanes"][1]).max())
    with pytest.raises(ValueError, match="scatter"):
        MPMSolver(soil, scene.domain, 0.03, scene.particles, scatter="vector")
