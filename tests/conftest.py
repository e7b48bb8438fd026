"""Test set-up: matplotlib draws off-screen (Agg) in every test."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")
