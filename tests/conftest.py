"""Test set-up: matplotlib draws off-screen (Agg) in every test; hypothesis has no time deadline; the
planner's on-disk NLP cache is off unless a test (or the caller's environment) sets it.

Tests assert behaviour, never wall time: hypothesis's default 200 ms deadline per example would make a
property test's verdict depend on how busy the machine is, so the profile loaded here has none.
"""

from __future__ import annotations

import os

import matplotlib
from hypothesis import settings

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
# the suite neither reads nor fills the user's on-disk NLP cache (tests/test_nlp_cache.py sets its own)
os.environ.setdefault("WHEELLOADER_NLP_CACHE", "off")

settings.register_profile("wheelloader", deadline=None)
settings.load_profile("wheelloader")
