"""Shared fixtures."""

from __future__ import annotations

import os

import matplotlib
import pytest

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def default_pile():
    from wheelloader.estimator import Pile

    return Pile.trapezoid()


@pytest.fixture(scope="session")
def default_bucket():
    from wheelloader.estimator import Bucket

    return Bucket()
