"""Where sweeps run: the ``--ray`` modes and their command-line option (light: imports neither Ray nor
the estimator, so ``wheelloader --help`` stays fast; the runner is :mod:`wheelloader.sweep`)."""

from __future__ import annotations

import argparse
import importlib.util

__all__ = ["LOCAL", "OFF", "add_ray_arguments", "default_ray_mode", "parse_ray_mode", "ray_available"]

#: Serial mode: no Ray.
OFF = "off"
#: Ray on this machine (``ray.init()`` with this machine's CPUs, or ``--ray-cpus``).
LOCAL = "local"


def ray_available() -> bool:
    """Whether Ray is installed (looked up without importing it)."""
    return importlib.util.find_spec("ray") is not None


def default_ray_mode() -> str:
    """``"local"`` when Ray is installed, else ``"off"``."""
    return LOCAL if ray_available() else OFF


def parse_ray_mode(text: str) -> str:
    """Validate a ``--ray`` value: ``off``, ``local``, ``auto``, ``ray://HOST:PORT`` or ``HOST:PORT``."""
    value = str(text).strip()
    if value.lower() in (OFF, LOCAL, "auto"):
        return value.lower()
    if value.startswith("ray://") and len(value) > len("ray://"):
        return value
    host, sep, port = value.rpartition(":")
    if sep and host and port.isdigit():
        return value
    raise ValueError(f"--ray must be 'off', 'local', 'auto', 'ray://HOST:PORT' or 'HOST:PORT', got {text!r}")


def _ray_mode_arg(text: str) -> str:
    try:
        return parse_ray_mode(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_ray_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--ray`` (default ``local`` with Ray installed, else ``off``) and ``--ray-cpus`` to ``parser``."""
    default = default_ray_mode()
    parser.add_argument("--ray", type=_ray_mode_arg, default=default, metavar="MODE",
                        help="run the units as Ray tasks: 'local' (ray.init() on this machine), 'auto' or "
                             "'ray://HOST:10001' (an existing cluster), or 'off' (serial, no Ray); default "
                             + ("'local' (Ray is installed)" if default == LOCAL
                                else "'off' (Ray is not installed: pip install -e \".[scale]\")"))
    parser.add_argument("--ray-cpus", type=int, default=None, metavar="N",
                        help="with --ray local: CPUs Ray may use, i.e. parallel units (default: all of this "
                             "machine's)")
