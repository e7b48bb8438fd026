"""Where a result was measured: machine, load and package versions (stamped into benchmark and training JSON)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from importlib import metadata
from pathlib import Path

#: Packages whose versions every record names (None when not installed).
PACKAGES = ("wheelloader", "numpy", "scipy", "casadi", "gymnasium", "matplotlib", "torch", "stable-baselines3")
#: BLAS thread settings that change small-matrix timings.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Vector instruction sets that choose OpenBLAS's kernels and NumPy's SIMD loops (docs/reproducibility.md).
CPU_FEATURES = ("sse4_2", "avx", "avx2", "fma", "avx512f", "asimd", "sve")
#: Settings that make this CPU run another CPU's kernels (how docs/reproducibility.md emulates other CPUs).
KERNEL_VARIABLES = ("OPENBLAS_CORETYPE", "NPY_DISABLE_CPU_FEATURES")


def machine_info() -> dict[str, object]:
    """Platform, CPU model, its vector instruction sets and count, load average, BLAS thread and kernel settings
    and package versions of this run."""
    versions: dict[str, str | None] = {}
    for pkg in PACKAGES:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    cpu = platform.processor() or ""
    flags: set[str] = set()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key = line.split(":", 1)[0].strip()
                if key == "model name" and not flags:
                    cpu = line.split(":", 1)[1].strip()
                elif key in ("flags", "Features"):  # x86-64, ARM
                    flags = set(line.split(":", 1)[1].split())
                    break
    except OSError:
        pass
    try:
        load: list[float] | None = list(os.getloadavg())
    except OSError:
        load = None
    return {
        "git": git_revision(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "cpu_features": [f for f in CPU_FEATURES if f in flags],
        "kernel_env": {k: os.environ[k] for k in KERNEL_VARIABLES if k in os.environ},
        "loadavg_1_5_15min": load,
        "blas_threads_env": {k: os.environ.get(k) for k in BLAS_THREAD_VARIABLES},
        "versions": versions,
    }


def git_revision(where: str | Path | None = None) -> dict[str, object] | None:
    """The git commit of the checkout at ``where`` (default: the working directory, else this package's
    source folder) and whether it has uncommitted changes; None outside a git checkout."""
    candidates = [Path(where)] if where is not None else [Path.cwd(), Path(__file__).resolve().parent]
    for folder in candidates:
        try:
            commit = subprocess.run(["git", "-C", str(folder), "rev-parse", "HEAD"], capture_output=True, text=True,
                                    timeout=10, check=True).stdout.strip()
            status = subprocess.run(["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
                                    capture_output=True, text=True, timeout=10, check=True).stdout
        except (OSError, subprocess.SubprocessError):
            continue
        return {"commit": commit, "dirty": bool(status.strip()), "checkout": str(folder)}
    return None


def load_label(machine: dict[str, object]) -> str:
    """The 1/5/15-minute load averages of a :func:`machine_info` record for report lines, e.g. "2.1/2.3/2.4"
    (empty where the platform has none)."""
    return "/".join(f"{v:.1f}" for v in machine.get("loadavg_1_5_15min") or [])  # type: ignore[union-attr]


def commit_label(machine: dict[str, object]) -> str:
    """The short git commit of a :func:`machine_info` record for report lines ("unknown" outside a checkout),
    with "(uncommitted changes)" when the checkout was dirty."""
    git = machine.get("git") or {}
    commit = str(git.get("commit") or "unknown")[:10]  # type: ignore[union-attr]
    return commit + (" (uncommitted changes)" if git.get("dirty") else "")  # type: ignore[union-attr]


#: The package's folders in the repository and where each lands in an importable tree (pyproject's package-dir):
#: the parent package first, then its subpackages into it.
PACKAGE_DIRS = {"src/wheelloader": "wheelloader", "estimator": "wheelloader/estimator", "envs": "wheelloader/envs",
                "planner": "wheelloader/planner"}


def package_at_revision(root: Path, rev: str, into: Path) -> tuple[str, Path]:
    """The package as it was at git revision ``rev`` of the repository ``root``, for a benchmark's baseline.

    ``git archive`` of :data:`PACKAGE_DIRS` at ``rev``, laid out under ``into`` as an importable ``wheelloader``.
    Returns the full commit and the directory to put first on ``PYTHONPATH``.
    """
    commit = subprocess.run(["git", "-C", str(root), "rev-parse", rev], capture_output=True, text=True,
                            check=True).stdout.strip()
    raw = into / "tree"
    raw.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(root), "archive", commit, *PACKAGE_DIRS], capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(raw)], input=archive, check=True)
    pkg = into / "pkg"
    pkg.mkdir()
    for src, dst in PACKAGE_DIRS.items():
        (raw / src).rename(pkg / dst)
    return commit, pkg
