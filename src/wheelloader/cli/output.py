"""Writing what a command produces: checked before any work, written atomically, never over an input.

Every subcommand declares its outputs and inputs up front with :func:`check_outputs` (before the slow
part runs), then writes each file through :func:`atomic_output`: into a temporary file in the same
directory, renamed over the target only when complete. A crash, a full disk or an interrupt leaves the
old file as it was and no half-written one behind. Importing this module imports nothing heavy, so
``wheelloader --help`` stays fast.
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

#: Help text of the ``--force`` flag every subcommand shares.
FORCE_HELP = "replace existing output files (never an input file)"


def add_force_flag(parser: Any) -> None:
    """Add ``--force`` (alias ``--overwrite``, its name before version 0.2) to a subcommand's parser."""
    parser.add_argument("--force", "--overwrite", dest="force", action="store_true", help=FORCE_HELP)


def check_outputs(outputs: Sequence[tuple[str, str | Path | None]], inputs: Sequence[str | Path | None] = (),
                  force: bool = False) -> list[Path]:
    """Check that every output can be written, before any work starts.

    Parameters
    ----------
    outputs : sequence of (flag, path)
        Each output with the option that named it (for messages); ``None`` paths are skipped.
    inputs : sequence of paths
        Files the command reads (a cycle log and its sidecar, params, pile files): never written over.
    force : bool
        Whether existing outputs may be replaced.

    Returns
    -------
    list of Path
        The outputs that are not None, in order.

    Raises
    ------
    ParameterError
        An output is a directory or not a regular file, its directory is missing, it is one of the
        inputs, two outputs share a path, or it exists and ``force`` is false.
    """
    from wheelloader.estimator import ParameterError

    resolved_inputs = {Path(p).resolve() for p in inputs if p is not None and Path(p).exists()}
    seen: dict[Path, str] = {}
    paths: list[Path] = []
    for flag, value in outputs:
        if value is None:
            continue
        path = Path(value)
        if path.is_dir():
            raise ParameterError(f"{flag} {path} is a directory; give a file name")
        if path.exists() and not stat.S_ISREG(path.stat().st_mode):
            raise ParameterError(f"{flag} {path} is not a regular file; give a file name")
        if not path.parent.is_dir():
            raise ParameterError(f"{flag}: output directory {path.parent} does not exist")
        real = path.resolve()
        if real in resolved_inputs:
            raise ParameterError(f"{flag} {path} is one of the input files; choose another name")
        if real in seen:
            raise ParameterError(f"output {path} is given twice ({seen[real]} and {flag}); choose different names")
        seen[real] = flag
        if path.exists() and not force:
            raise ParameterError(f"output {path} exists; pass --force to replace it")
        paths.append(path)
    return paths


@contextmanager
def atomic_output(target: str | Path) -> Iterator[Path]:
    """A temporary path beside ``target`` (same suffix) that replaces ``target`` when the block succeeds.

    The temporary file is removed when the block raises; ``target`` is then untouched.
    """
    target = Path(target)
    tmp = target.with_name(f".{target.stem}.partial-{os.getpid()}{target.suffix}")
    try:
        try:
            yield tmp
            if not tmp.exists():
                raise OSError(f"nothing was written to {target}")
            os.replace(tmp, target)
        except OSError as exc:  # name the file the user asked for, not the temporary one
            if exc.errno is None:
                raise
            raise OSError(exc.errno, exc.strerror, str(target)) from exc
    finally:
        tmp.unlink(missing_ok=True)


def write_json(target: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON atomically (NumPy values as Python ones, NaN/inf as null)."""
    from wheelloader.estimator.jsonable import to_jsonable

    text = json.dumps(to_jsonable(data), indent=1, allow_nan=False) + "\n"
    with atomic_output(target) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(target)


def fresh_directory(requested: str | Path, force: bool = False) -> Path:
    """Create and return an output directory.

    If ``requested`` exists and is not empty and ``force`` is false, a
    new sibling ``NAME-2``, ``NAME-3``, ... is used instead, so earlier
    results are never replaced without asking.
    """
    from wheelloader.estimator import ParameterError

    path = Path(requested)
    if path.exists() and not path.is_dir():
        raise ParameterError(f"output directory {path} exists and is not a directory; choose another name")
    if force or not path.exists() or not any(path.iterdir()):
        path.mkdir(parents=True, exist_ok=True)
        return path
    k = 2
    while True:
        candidate = path.with_name(f"{path.name}-{k}")
        if not candidate.exists():
            candidate.mkdir(parents=True)
            return candidate
        k += 1
