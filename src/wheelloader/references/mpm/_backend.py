"""Lazy access to Taichi: imported and initialised only when a solver is built.

``import wheelloader.references.mpm`` never imports Taichi; the first solver calls :func:`taichi_module`,
which imports it (or raises :class:`MPMUnavailableError` with the install command) and runs ``ti.init``
once per process on the CPU backend.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from wheelloader.estimator import WheelloaderError

#: The install command named by the error when Taichi is missing.
INSTALL_HINT = 'pip install "wheelloader[mpm]"'
#: The Taichi version the solver was written and verified against.
TAICHI_VERSION = "1.7.4"

_STATE: dict[str, Any] = {"ti": None, "threads": None}


class MPMUnavailableError(WheelloaderError, ImportError):
    """Taichi (the optional ``mpm`` extra) is not installed."""


def taichi_available() -> bool:
    """Whether ``import taichi`` would succeed (without importing it)."""
    from importlib.util import find_spec

    return find_spec("taichi") is not None


def taichi_module(threads: int = 1) -> ModuleType:
    """Import Taichi and initialise it once (CPU, ``threads`` worker threads, default float 32 bit).

    Parameters
    ----------
    threads : int
        ``cpu_max_num_threads`` of the first initialisation. Later calls with another count keep the
        first one (Taichi is initialised once per process) and say so in the returned module's state.

    Raises
    ------
    MPMUnavailableError
        When Taichi is not installed.
    ValueError
        When ``threads`` is not a positive integer.
    """
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    if _STATE["ti"] is not None:
        return _STATE["ti"]
    try:
        import taichi as ti
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise MPMUnavailableError(
            f"the MPM reference plant needs Taichi {TAICHI_VERSION}; install it with:  {INSTALL_HINT}") from exc
    ti.init(arch=ti.cpu, cpu_max_num_threads=threads, default_fp=ti.f32, random_seed=0, log_level=ti.WARN)
    _STATE["ti"] = ti
    _STATE["threads"] = threads
    return ti


def initialised_threads() -> int | None:
    """The thread count Taichi was initialised with in this process (None before the first solver)."""
    return _STATE["threads"]
