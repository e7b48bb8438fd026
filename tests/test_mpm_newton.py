"""The Newton implicit-MPM blade cross-check: set-up without Newton, and (slow) a coarse run."""

from __future__ import annotations

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from wheelloader.references.mpm import ContinuumSoil
from wheelloader.references.mpm.newton_blade import (
    NEWTON_INSTALL_HINT,
    NewtonBladeSettings,
    drucker_prager_friction,
    newton_available,
    run_newton_blade,
)
from wheelloader.references.mpm.verification import blade_motion, mckyes_blade

SOIL = ContinuumSoil(1600.0, math.radians(30.0), wall_friction_angle=math.radians(20.0))


def _need_newton() -> None:
    if not newton_available():
        if os.environ.get("WHEELLOADER_REQUIRE_NEWTON") == "1":
            pytest.fail(f"WHEELLOADER_REQUIRE_NEWTON=1 but newton/warp are not installed ({NEWTON_INSTALL_HINT})")
        pytest.skip(f"newton not installed: {NEWTON_INSTALL_HINT} (set WHEELLOADER_REQUIRE_NEWTON=1 to fail)")


def test_module_imports_without_newton_and_names_the_extra():
    # newton and warp blocked: importing works, running raises the error naming the extra
    code = ("import sys; sys.modules['newton'] = None; sys.modules['warp'] = None\n"
            "import math\n"
            "from wheelloader.references.mpm import ContinuumSoil\n"
            "from wheelloader.references.mpm.newton_blade import NewtonUnavailableError, run_newton_blade\n"
            "try:\n"
            "    run_newton_blade(0.1, ContinuumSoil(1600.0, math.radians(30.0)), 0.02)\n"
            "except NewtonUnavailableError as exc:\n"
            "    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert NEWTON_INSTALL_HINT in out.stdout


def test_plane_strain_friction_match():
    # sqrt(J2) = (s1 - s3) / 2 and p = (s1 + s3) / 2 in plastic plane strain without dilatancy
    assert drucker_prager_friction(math.radians(30.0)) == pytest.approx(0.5)


def test_bad_input_is_rejected_before_newton_is_needed():
    with pytest.raises(ValueError, match="cohesionless"):
        run_newton_blade(0.1, ContinuumSoil(1600.0, math.radians(30.0), cohesion=1000.0), 0.01)
    with pytest.raises(ValueError, match="depth"):
        run_newton_blade(0.0, SOIL, 0.01)
    with pytest.raises(ValueError, match="dx"):
        run_newton_blade(0.1, SOIL, 0.2)
    with pytest.raises(ValueError, match="whole number"):
        run_newton_blade(0.1, SOIL, 0.01, settings=NewtonBladeSettings(dt=0.007))
    with pytest.raises(ValueError, match="cells_across"):
        NewtonBladeSettings(cells_across=0)
    with pytest.raises(ValueError, match="dt"):
        NewtonBladeSettings(dt=-1.0)


def test_blade_motion_is_the_taichi_case():
    travel, duration, position = blade_motion(0.15)
    assert travel == pytest.approx(0.18)
    assert duration == pytest.approx(0.05 + 0.18 / 0.2)
    assert float(position(duration)) == pytest.approx(travel)
    assert float(position(-1.0)) == 0.0


@pytest.mark.slow
def test_newton_blade_force_is_positive_and_grows_with_depth():
    _need_newton()
    settings = NewtonBladeSettings()
    forces = []
    for depth in (0.10, 0.15):
        res = run_newton_blade(depth, SOIL, 0.025, travel=depth, settings=settings)
        assert res.extra["finite"]
        # the static colliders carry the bed's weight after settling (the impulse accounting; 0.95 after 0.1 s)
        assert res.extra["floor_reaction_over_weight"] == pytest.approx(1.0, rel=0.1)
        travel = res.extra["travel"]
        window = (travel >= 0.5 * depth) & (travel <= depth)
        horizontal = float(-np.mean(res.force[window, 0]))
        assert np.all(np.isfinite(res.force))
        # coarse (4-6 cells over the cut): the order of the passive wedge (Newton measured 0.45-0.7x McKyes)
        assert 0.3 < horizontal / mckyes_blade(depth, SOIL)["horizontal"] < 2.0
        # soil slides up the blade: it lifts it
        assert float(np.mean(res.force[window, 1])) > 0.0
        forces.append(horizontal)
    # the wedge force scales with d^2 (2.25x from 0.10 to 0.15 m)
    assert forces[1] > 1.5 * forces[0]
