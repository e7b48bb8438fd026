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


# --- opt-in per-test CPU-time report (--cpu-durations=N) -----------------------------------------------------
# Wall time follows the machine's load; the CPU time a test spends (this process and the child processes it
# waited for, e.g. a CLI run in a subprocess) does not, so it is the figure that decides which tests belong to
# the slow suite (docs/guide/testing.md). Measured around each test's setup and call; with pytest-xdist each
# worker measures its own tests and the controller sums them.


def pytest_addoption(parser):
    parser.addoption(
        "--cpu-durations",
        type=int,
        default=None,
        metavar="N",
        help="report the N tests with the most CPU time (setup + call; this process and its waited-for children, "
        "user + system); N=0 lists every test. Off by default.",
    )


def _cpu_seconds() -> float:
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


_CPU_KEY = pytest.StashKey[float]()
_cpu_records: list[tuple[str, str, float]] = []  # (test id, worker, CPU seconds), filled on the controller


def _measure_cpu(item):
    if item.config.getoption("--cpu-durations") is None:
        yield
        return
    start = _cpu_seconds()
    try:
        yield
    finally:
        item.stash[_CPU_KEY] = item.stash.get(_CPU_KEY, 0.0) + _cpu_seconds() - start


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_setup(item):
    yield from _measure_cpu(item)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_call(item):
    yield from _measure_cpu(item)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    if call.when == "teardown" and _CPU_KEY in item.stash:
        outcome.get_result().user_properties.append(("cpu_s", item.stash[_CPU_KEY]))


def pytest_runtest_logreport(report):
    if report.when != "teardown":
        return
    cpu = dict(report.user_properties).get("cpu_s")
    if cpu is None:
        return
    node = getattr(report, "node", None)  # the xdist worker that ran it (absent without xdist)
    worker = getattr(getattr(node, "gateway", None), "id", "main")
    _cpu_records.append((report.nodeid, worker, float(cpu)))


def pytest_terminal_summary(terminalreporter, config):
    n = config.getoption("--cpu-durations")
    if n is None:
        return
    tr = terminalreporter
    records = sorted(_cpu_records, key=lambda r: -r[2])
    tr.write_sep("=", f"slowest {'all' if n == 0 else n} CPU durations (setup + call, incl. waited-for children)")
    for nodeid, worker, cpu in records if n == 0 else records[:n]:
        tr.write_line(f"{cpu:9.2f}s cpu  [{worker}] {nodeid}")
    per_worker: dict[str, float] = {}
    for _, worker, cpu in records:
        per_worker[worker] = per_worker.get(worker, 0.0) + cpu
    for worker, total in sorted(per_worker.items()):
        tr.write_line(f"worker {worker}: {total:.1f} s CPU in tests")
    tr.write_line(f"all tests: {sum(per_worker.values()):.1f} s CPU ({len(records)} tests)")
