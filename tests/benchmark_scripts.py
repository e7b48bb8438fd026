"""Import a script of ``benchmarks/`` as a module in a test (the benchmarks are leaf scripts, not a package)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` executed as the module ``wheelloader_benchmark_<name>`` (a new module per call)."""
    spec = importlib.util.spec_from_file_location(f"wheelloader_benchmark_{name}", BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
