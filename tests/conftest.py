"""Test set-up: matplotlib draws off-screen (Agg) in every test; hypothesis has no time deadline; the
planner's on-disk NLP cache is off unless a test (or the caller's environment) sets it.

Tests assert behaviour, never wall time: hypothesis's default 200 ms deadline per example would make a
property test's verdict depend on how busy the machine is, so the profile loaded here has none.
"""

from __future__ import annotations

import os

import matplotlib
import numpy as np
import pytest
from hypothesis import settings

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
# the suite neither reads nor fills the user's on-disk NLP cache (tests/test_nlp_cache.py sets its own)
os.environ.setdefault("WHEELLOADER_NLP_CACHE", "off")

settings.register_profile("wheelloader", deadline=None)
settings.load_profile("wheelloader")


@pytest.fixture
def assert_fit_jacobian():
    """``check(data, p)``: the fit model's analytic Jacobian (``FitData.forces_and_jacobian``) equals central
    finite differences of ``FitData.forces`` in every fit parameter, to 1e-5 of the largest derivative."""
    from wheelloader.estimator.calibration.fitmodel import FIT_NAMES

    def check(data, p):
        _, _, jt, jn = data.forces_and_jacobian(p)
        jac = np.vstack([jt, jn])
        for j in range(len(FIT_NAMES)):
            h = 1e-6 * max(abs(p[j]), 1.0 if j not in (3, 4, 6) else 0.1)
            up, dn = p.copy(), p.copy()
            up[j] += h
            dn[j] -= h
            fd = (np.concatenate(data.forces(up)[:2]) - np.concatenate(data.forces(dn)[:2])) / (2 * h)
            assert np.max(np.abs(jac[:, j] - fd)) <= 1e-5 * (np.max(np.abs(fd)) + 1e-12), FIT_NAMES[j]

    return check
