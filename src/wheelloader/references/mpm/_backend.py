"""Lazy access to Taichi: imported and initialised only when a solver is built.

``import wheelloader.references.mpm`` never imports Taichi; the first solver calls :func:`taichi_module`,
which imports it (or raises :class:`MPMUnavailableError` with the install command) and runs ``ti.init``
once per process: on the CPU by default; ``backend="gpu"`` asks for one of Taichi's GPU backends (CUDA,
Vulkan, Metal, OpenGL; an error where none works) and ``backend="auto"`` takes a GPU where Taichi finds
one and the CPU otherwise.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

from wheelloader.estimator import WheelloaderError

#: The install command named by the error when Taichi is missing.
INSTALL_HINT = 'pip install "wheelloader[mpm]"'
#: The Taichi version the solver was written and verified against.
TAICHI_VERSION = "1.7.4"

#: The backend choices of :func:`taichi_module`.
BACKENDS = ("cpu", "gpu", "auto")

_STATE: dict[str, Any] = {"ti": None, "threads": None, "backend": None}


class MPMUnavailableError(WheelloaderError, ImportError):
    """Taichi (the optional ``mpm`` extra) is not installed."""


def taichi_available() -> bool:
    """Whether ``import taichi`` would succeed (without importing it)."""
    from importlib.util import find_spec

    return find_spec("taichi") is not None


def taichi_module(threads: int = 1, backend: str = "cpu") -> ModuleType:
    """Import Taichi and initialise it once (``threads`` CPU worker threads, default float 32 bit).

    Parameters
    ----------
    threads : int
        ``cpu_max_num_threads`` of the first initialisation. Later calls with another count keep the
        first one (Taichi is initialised once per process); :func:`initialised_threads` says which.
    backend : str
        ``"cpu"``, ``"gpu"`` or ``"auto"`` (see the module docstring), at the first initialisation only;
        :func:`initialised_backend` says which one runs.

    Raises
    ------
    MPMUnavailableError
        When Taichi is not installed.
    ValueError
        When ``threads`` is not a positive integer or ``backend`` not one of :data:`BACKENDS`.
    RuntimeError
        When ``backend="gpu"`` and Taichi finds no GPU backend.
    """
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if _STATE["ti"] is not None:
        return _STATE["ti"]
    try:
        import taichi as ti
    except ImportError as exc:  # pragma: no cover - exercised only without the extra
        raise MPMUnavailableError(
            f"the MPM reference plant needs Taichi {TAICHI_VERSION}; install it with:  {INSTALL_HINT}") from exc
    arch = ti.cpu if backend == "cpu" else ti.gpu
    ti.init(arch=arch, cpu_max_num_threads=threads, default_fp=ti.f32, random_seed=0, log_level=ti.WARN)
    chosen = ti.lang.impl.current_cfg().arch
    running = "cpu" if chosen in (ti.x64, ti.arm64) else chosen.name
    if backend == "gpu" and running == "cpu":
        ti.reset()
        raise RuntimeError("backend='gpu' but Taichi found no GPU backend (CUDA, Vulkan, Metal, OpenGL); "
                           "use backend='cpu' or 'auto'")
    _STATE["ti"] = ti
    _STATE["threads"] = threads
    _STATE["backend"] = running
    return ti


def initialised_threads() -> int | None:
    """The thread count Taichi was initialised with in this process (None before the first solver)."""
    return _STATE["threads"]


def initialised_backend() -> str | None:
    """``"cpu"`` or the GPU backend's name (``"cuda"``, ``"vulkan"``, ...) Taichi runs on (None before the first
    solver)."""
    return _STATE["backend"]
