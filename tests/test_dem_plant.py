"""The DEM as a plant of the adaptation loop (``DEMPlant``): input checks always; two tiny digs with Yade.

The digs use the CI scenario's coarse spheres (``tiny_config``: about 350 spheres, ~20 s a cycle here) and
skip without Yade (``WHEELLOADER_REQUIRE_YADE=1``, set by ``.ci/run``, turns the skip into a failure).
"""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from wheelloader.estimator import BucketPath, ParameterError, Pile, default_path
from wheelloader.references import Plant, dem

_REQUIRED = os.environ.get("WHEELLOADER_REQUIRE_YADE", "") not in ("", "0")
needs_yade = pytest.mark.skipif(shutil.which(os.environ.get("WHEELLOADER_YADE", "yade")) is None and not _REQUIRED,
                                reason=f"Yade DEM engine not installed (install with: {dem.YADE_INSTALL})")


def test_dem_plant_is_a_plant_and_checks_its_input():
    plant = dem.DEMPlant(dem.tiny_config())
    assert isinstance(plant, Plant) and plant.name == "dem"
    path, pile = default_path(), Pile.trapezoid()
    with pytest.raises(ParameterError, match="its own soils"):
        plant.dig(path, pile, "clay")
    with pytest.raises(ParameterError, match="cohesive"):
        plant.dig(path, pile, "dirt")  # similarity scaling holds for cohesionless soils only
    with pytest.raises(ParameterError, match="seed"):
        plant.dig(path, pile, "gravel", seed=-1)
    with pytest.raises(ParameterError, match="BucketPath"):
        plant.dig("path", pile, "gravel")
    with pytest.raises(ParameterError, match="DemConfig"):
        dem.DEMPlant("tiny")


@pytest.mark.yade
@needs_yade
def test_two_cycles_on_the_pile_the_first_one_carved(tmp_path):
    plant = dem.DEMPlant(dem.tiny_config(), cache_dir=tmp_path / "cache")
    path = default_path()
    first = plant.dig(path, Pile.trapezoid(), "gravel", seed=0)
    second = plant.dig(path, first.pile_after, "gravel", seed=0)
    for log in (first, second):
        assert isinstance(log.path, BucketPath) and np.array_equal(log.path.t, path.t)
        # the measured tip pose, scaled back to full scale, follows the requested path within a few cm
        assert np.max(np.hypot(log.path.x - path.x, log.path.z - path.z)) < 0.1
        assert np.all(np.isfinite(log.tangential)) and np.all(np.isfinite(log.normal))
        assert np.max(np.hypot(log.tangential, log.normal)) > 1e3  # full-scale forces [N], not a slab's
        assert 0.0 < log.fill_volume[-1] < log.bucket.capacity
        assert log.bucket.width == 1.0 and log.metadata["plant"] == "dem" and log.metadata["scale"] == 0.4
    # each cycle starts on the pile it was given; the carved pile changes only where the scenario dug
    assert second.pile == first.pile_after
    lo, hi = first.metadata["scenario_range_m"]
    x = first.pile.x
    behind = x > hi  # (in front the relaxation to the friction angle may reach a little past the range)
    np.testing.assert_array_equal(first.pile_after.heights[behind], first.pile.heights[behind])
    assert np.all(first.pile_after.heights[x < lo - 0.2] >= -0.1)
    assert np.max(np.abs(first.pile_after.heights - first.pile.heights)) > 0.05
    # the same seed and pile dig the same cycle (bit-reproducible with one Yade thread)
    again = plant.dig(path, Pile.trapezoid(), "gravel", seed=0)
    np.testing.assert_array_equal(again.tangential, first.tangential)
