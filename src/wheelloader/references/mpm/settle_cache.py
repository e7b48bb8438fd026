"""Settled piles on disk: the solver's state after settling, keyed by a digest of everything it depends on.

The plant lets its soil settle under gravity (``settle_time``, about 2000 steps at dx 2 cm) before every
cycle. A scene dug again (the same pile, path start, seed, soil and settings: a rerun, a benchmark, an
old-against-new comparison, a regenerated reference) settles to the same state bit for bit, so the state
is kept in a user cache directory and restored on the next dig instead of computed. The digest
(:func:`settle_digest`) covers the particles, the soil, the tool and its first pose, the numerical
settings, the kernels' mode and lane count, the backend, the Taichi version and the source of the solver's
kernels, so a change to any of them misses the cache. A hit continues bit for bit as a miss would
(``tests/test_mpm.py``).

Directory: ``$WHEELLOADER_MPM_CACHE``, else ``$XDG_CACHE_HOME/wheelloader/mpm``, else
``~/.cache/wheelloader/mpm``; never inside shipped data. At most :data:`MAX_ENTRIES` states are kept
(the least recently used go first; about 1.2 MB each at dx 2 cm). A cache that cannot be written is
skipped with a warning.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

#: Environment variable naming the cache directory.
CACHE_ENV = "WHEELLOADER_MPM_CACHE"
#: States kept at most (least recently used removed first).
MAX_ENTRIES = 64
#: Layout of a cached state; part of the digest.
FORMAT = 1
_SOURCES = ("solver.py", "_kernels.py", "_legacy.py")


def default_cache_dir() -> Path:
    """The cache directory (see the module docstring)."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wheelloader" / "mpm"


def _kernel_source_digest() -> str:
    here = Path(__file__).parent
    h = hashlib.sha256()
    for name in _SOURCES:
        h.update((here / name).read_bytes())
    return h.hexdigest()


def settle_digest(arrays: dict[str, np.ndarray], values: dict[str, Any]) -> str:
    """SHA-256 over named arrays (their dtype, shape and bytes) and JSON-able values, with the kernels' source."""
    h = hashlib.sha256()
    h.update(json.dumps({"format": FORMAT, "kernels": _kernel_source_digest(), **values}, sort_keys=True,
                        default=repr).encode())
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


class SettleCache:
    """Solver states (:meth:`~.solver.MPMSolver.state`) in ``directory``, one ``.npz`` per digest.

    Parameters
    ----------
    directory : str or Path, optional
        Default :func:`default_cache_dir`.
    max_entries : int
        States kept at most.
    """

    def __init__(self, directory: str | Path | None = None, max_entries: int = MAX_ENTRIES) -> None:
        self.directory = Path(directory) if directory is not None else default_cache_dir()
        if isinstance(max_entries, bool) or not isinstance(max_entries, int) or max_entries < 1:
            raise ValueError(f"max_entries must be a positive integer, got {max_entries!r}")
        self.max_entries = max_entries

    def _file(self, digest: str) -> Path:
        return self.directory / f"settled-{digest[:32]}.npz"

    def load(self, digest: str) -> dict[str, np.ndarray] | None:
        """The state stored under ``digest``, or None (absent or unreadable)."""
        target = self._file(digest)
        try:
            with np.load(target, allow_pickle=False) as data:
                if str(data["digest"]) != digest:
                    return None
                state = {k: data[k] for k in data.files if k != "digest"}
            os.utime(target)
            return state
        except (OSError, KeyError, ValueError):
            return None

    def save(self, digest: str, state: dict[str, np.ndarray]) -> Path | None:
        """Store ``state`` under ``digest`` (atomically); the file, or None when the directory is not writable."""
        target = self._file(digest)
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".settled-", suffix=".npz", dir=self.directory)
            try:
                with os.fdopen(fd, "wb") as handle:
                    np.savez(handle, digest=np.array(digest), **state)
                os.replace(tmp, target)
            finally:
                if os.path.exists(tmp):
                    os.unlink(tmp)
            self._prune()
            return target
        except OSError as exc:
            warnings.warn(f"MPM settle cache {self.directory} not writable ({exc}); settling is not cached",
                          RuntimeWarning, stacklevel=2)
            return None

    def _prune(self) -> None:
        def mtime(path: Path) -> float:
            try:
                return path.stat().st_mtime
            except OSError:
                return 0.0

        entries = sorted(self.directory.glob("settled-*.npz"), key=mtime, reverse=True)
        for old in entries[self.max_entries:]:
            try:
                old.unlink()
            except OSError:
                pass
