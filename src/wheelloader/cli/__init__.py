"""The ``wheelloader`` command line: one package, one module per subcommand.

Each module listed in :data:`COMMAND_MODULES` exposes ``register(subparsers)``, which adds its parsers
and sets ``func`` (a callable taking the parsed arguments and returning an exit code). Heavy imports
happen inside the handlers, so ``wheelloader --help`` stays fast. Every subcommand shares the output
rules of :mod:`wheelloader.cli.output` (checked before work, atomic, ``--force``, never over an input).
Exit status: 0 success, 1 ran but the result is not usable (the output says why), 2 bad input or an
error reading or writing a file (one ``wheelloader: error:`` line, no traceback), 130 interrupted (Ctrl-C:
the line ``wheelloader: interrupted``, no output written, every earlier file as it was).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
from typing import NoReturn

from wheelloader import __version__

#: Modules that contribute subcommands, in help order.
COMMAND_MODULES: tuple[str, ...] = (
    "wheelloader.cli.demo",
    "wheelloader.cli.calibrate",
    "wheelloader.cli.plan",
    "wheelloader.cli.dem",
)


def _one_line(text: object) -> str:
    """``text`` on one line: control characters (a newline in a file name) written as escapes."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))


def _error(text: object) -> int:
    print(f"wheelloader: error: {_one_line(text)}", file=sys.stderr)
    return 2


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one ``wheelloader: error:`` line (exit status 2)."""

    def error(self, message: str) -> NoReturn:
        command = self.prog.removeprefix("wheelloader").strip()
        where = f"{command}: " if command else ""
        self.exit(2, f"wheelloader: error: {_one_line(where + message)} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    parser = _Parser(
        prog="wheelloader",
        description="Soil-force estimation, simulation and planning for wheel-loader bucket loading.",
    )
    parser.add_argument("--version", action="version", version=f"wheelloader {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0,
                        help="log the library's progress (calibration stages, DEM runs); -vv: debug detail")
    parser.add_argument("-q", "--quiet", action="store_true", help="log errors only (no warnings)")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def _configure_logging(verbose: int, quiet: bool) -> None:
    level = logging.ERROR if quiet else {0: logging.WARNING, 1: logging.INFO}.get(verbose, logging.DEBUG)
    logging.basicConfig(level=level, format="%(message)s" if level > logging.DEBUG else "%(name)s: %(message)s",
                        stream=sys.stderr, force=True)
    logging.getLogger("wheelloader").setLevel(level)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``wheelloader`` console script."""
    # Small dense problems (281-sample fits, 8 parameters) run several times slower with a multi-threaded
    # BLAS on a 2-core machine; default to one thread unless the user chose otherwise.
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if not hasattr(args, "func"):
            parser.print_help()
            return 2
        _configure_logging(args.verbose, args.quiet)
        from wheelloader.estimator.errors import WheelloaderError  # after parsing: --help imports no estimator

        from .staging import command_scope
    except KeyboardInterrupt:
        print("wheelloader: interrupted", file=sys.stderr)
        return 130
    try:
        with command_scope(program=argv is None):
            return _run(args, WheelloaderError)
    except KeyboardInterrupt:  # between the command's own handling and the end of the scope
        print("wheelloader: interrupted", file=sys.stderr)
        return 130


def _run(args: argparse.Namespace, WheelloaderError: type[Exception]) -> int:  # noqa: N803 - an error class
    try:
        return int(args.func(args) or 0)
    except WheelloaderError as exc:
        return _error(exc)
    except BrokenPipeError:  # output piped into a reader that closed early (e.g. `| head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except FileNotFoundError as exc:
        return _error(f"file not found: {exc.filename}")
    except OSError as exc:
        where = f": {exc.filename}" if exc.filename else ""
        return _error(f"{exc.strerror or exc}{where}")
    except KeyboardInterrupt:  # Ctrl-C: every output was staged and is discarded (wheelloader.cli.staging)
        print("wheelloader: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
