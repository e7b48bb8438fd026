"""Writing what a command produces: checked before any work, written atomically, never over an input.

Every subcommand declares its outputs and inputs up front through :class:`~wheelloader.cli.staging.OutputRun`
(before the slow part runs; :func:`check_outputs` is its check alone), writes into a staging directory and
moves the outputs into place when it finishes. :func:`atomic_output` writes one file the same way: into a
temporary file in the same directory, renamed over the target only when complete. A crash, a full disk or
an interrupt leaves the old file as it was and no half-written one behind. Importing this module imports
nothing heavy, so ``wheelloader --help`` stays fast.
"""

from __future__ import annotations

import json
import os
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
    from .staging import OutputRun

    run = OutputRun(force=force, inputs=inputs)
    return [p for p in (run.file(flag, value) for flag, value in outputs) if p is not None]


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
