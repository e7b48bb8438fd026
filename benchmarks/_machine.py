"""Machine and version information stamped into every benchmark JSON (see :mod:`wheelloader.provenance`)."""

from wheelloader.provenance import machine_info

__all__ = ["machine_info"]
