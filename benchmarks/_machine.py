"""Machine and version information stamped into every benchmark JSON."""

from __future__ import annotations

import os
import platform
import sys
from importlib import metadata


def machine_info() -> dict[str, object]:
    """Platform, CPU and package versions of this run."""
    versions = {}
    for pkg in ("wheelloader", "numpy", "scipy", "casadi", "gymnasium", "matplotlib", "torch", "stable-baselines3"):
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    cpu = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "versions": versions,
    }
