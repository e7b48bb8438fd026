"""The ``wheelloader`` command line.

Each subcommand lives in the module that owns its idea; a module listed in
:data:`COMMAND_MODULES` exposes ``register(subparsers)`` that adds its
parsers and sets ``func`` (a callable taking the parsed arguments and
returning an exit code). Heavy imports happen inside the handlers, so
``wheelloader --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from . import __version__

#: Modules that contribute subcommands, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "wheelloader.demo",
    "wheelloader.estimator.commands",
    "wheelloader.planner.commands",
)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every available subcommand."""
    parser = argparse.ArgumentParser(
        prog="wheelloader",
        description="Soil-force estimation, simulation and planning for wheel-loader bucket loading.",
    )
    parser.add_argument("--version", action="version", version=f"wheelloader {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # module not written yet: its commands are simply absent
                continue
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wheelloader`` console script."""
    # Small dense problems (281-sample fits, 8 parameters) run several times slower with a multi-threaded
    # BLAS on a 2-core machine; default to one thread unless the user chose otherwise.
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    from wheelloader.estimator.errors import WheelloaderError

    parser = build_parser()
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except WheelloaderError as exc:
        print(f"wheelloader: error: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"wheelloader: error: file not found: {exc.filename}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        print("wheelloader: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
