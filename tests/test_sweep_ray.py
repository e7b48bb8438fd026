"""The sweep runner on Ray: a tiny sweep of 4 calibrations and 2 adaptation loops as Ray tasks on a local
``ray.init(num_cpus=2)`` gives the serial results, and a failing task is retried once and reported.

Needs the optional ``scale`` extra (``pip install -e ".[scale]"``); skipped without it unless
``WHEELLOADER_REQUIRE_RAY=1`` (CI installs the extra and sets it: a missing install fails). One test
function holds one Ray session, so that ``pytest -n 2`` never starts two local Ray clusters.
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import pytest

from wheelloader.adaptation import strategy_loop
from wheelloader.estimator import CalibrationOptions, SoilParams, calibrate, preset
from wheelloader.references.dem import filtered, load_reference
from wheelloader.sweep import Unit, run_sweep

if os.environ.get("WHEELLOADER_REQUIRE_RAY") == "1":  # CI sets this after installing the extra: no silent skip
    import ray
else:
    ray = pytest.importorskip("ray", reason='install the Ray extra: pip install -e ".[scale]"')

pytestmark = pytest.mark.ray

DATA = Path(__file__).resolve().parents[1] / "data" / "reference"
#: Timing fields of a cycle record (wall-clock: differ between runs); everything else must be equal.
TIMES = {"calibration_s", "planning_s", "between_cycles_s"}


def flaky(x: int, marker: str) -> int:
    """Fails on its first call (a file marks it), succeeds on the retry: in another process too."""
    path = Path(marker)
    if not path.exists():
        path.write_text("tried")
        raise OSError("transient failure")
    return x


def broken(x: int) -> int:
    raise ValueError(f"bad input {x}")


def _units() -> list[Unit]:
    logs = [filtered(load_reference(f"gravel_path{k}", DATA), 0.1) for k in (1, 2, 3, 4)]
    cal = [Unit(calibrate, {"cycles": log, "options": CalibrationOptions(method=method)}, label=f"calibrate path {k}")
           for k, (log, method) in enumerate(zip(logs, ("default", "multi-stage", "default", "single-stage"),
                                                 strict=True), start=1)]
    hidden = preset("dirt").replace(phi=preset("dirt").phi + 0.03)
    truth = {"compaction": 0.5, "stone_rate": 0.5, "stone_force": 3000.0, "drift": 0.05}
    loops = [Unit(strategy_loop, {"soil": hidden, "pile": {"shape": "trapezoid", "angle": math.radians(35.0)},
                                  "truth": truth, "strategy": name, "cycles": 2, "seed": 3, "planner": planner},
                  label=f"loop {name}")
             for name, planner in (("ours", "plan"), ("paper", None))]
    return cal + loops


def _comparable(values: list) -> list:
    out = []
    for v in values[:4]:
        assert v.success, v.message
        out.append((v.params.to_dict(), v.sinkage_modulus, v.cost, v.quality.rmse_r, v.nfev))
    for records in values[4:]:
        out.append([{k: x for k, x in r.items() if k not in TIMES} for r in records])
    return out


def test_ray_sweep_equals_serial_and_reports_failures(tmp_path):
    units = _units()
    serial = run_sweep(units, "off")
    assert serial.ok
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR")
    try:
        lines: list[str] = []
        parallel = run_sweep(units, "local", progress=lines.append)  # uses the session started above
        assert ray.is_initialized()  # left running: the runner did not start it
        assert parallel.ok and parallel.mode == "ray local" and parallel.workers == 2
        assert _comparable(parallel.values) == _comparable(serial.values)
        assert isinstance(parallel.values[0].params, SoilParams)
        assert sum(line.startswith("[") for line in lines) == len(units)
        # a failing task is retried once (in a worker, maybe another one), then reported with its error; the
        # workers cannot import this test module, so its functions travel by value
        ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
        mixed = [Unit(flaky, {"x": 1, "marker": str(tmp_path / "m")}, label="flaky"),
                 Unit(broken, {"x": 2}, label="broken")]
        result = run_sweep(mixed, "local", progress=lines.append)
        assert result.values == [1, None] and result.retried == [0, 1]
        assert [(f.index, f.label, f.attempts) for f in result.failures] == [(1, "broken", 2)]
        assert "ValueError: bad input 2" in result.failures[0].error
    finally:
        ray.shutdown()
