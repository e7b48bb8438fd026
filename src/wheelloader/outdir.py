"""Output directories that never overwrite what a user already has."""

from __future__ import annotations

from pathlib import Path


def fresh_directory(requested: str | Path, overwrite: bool = False) -> Path:
    """Create and return an output directory.

    If ``requested`` exists and is not empty and ``overwrite`` is false, a
    new sibling ``NAME-2``, ``NAME-3``, ... is used instead, so earlier
    results are never replaced without asking.
    """
    path = Path(requested)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{path} exists and is not a directory")
    if overwrite or not path.exists() or not any(path.iterdir()):
        path.mkdir(parents=True, exist_ok=True)
        return path
    k = 2
    while True:
        candidate = path.with_name(f"{path.name}-{k}")
        if not candidate.exists():
            candidate.mkdir(parents=True)
            return candidate
        k += 1
