"""On-disk cache of the planner's built NLP: built once per machine, not once per process.

Building the NLP (:func:`wheelloader.planner.nlp.build`) spends most of its time in CasADi's automatic
differentiation (the Jacobian and Hessian IPOPT needs). This module stores what the build returns (the
IPOPT solver, the ``forces`` and ``outputs`` functions and the constraint layout) with CasADi's own
serialisation (:class:`casadi.FileSerializer`) and loads it in later processes. A loaded solver is the
same expression graph evaluated by the same virtual machine, so plans are bit-identical with and without
the cache (tested).

Where: ``$WHEELLOADER_NLP_CACHE`` if set (a directory; ``off``, ``0``, ``false``, ``no`` or an empty
value disable the cache), else ``$XDG_CACHE_HOME/wheelloader/nlp``, else ``~/.cache/wheelloader/nlp``.

Key: the bucket, loader and planner options (their ``repr``: every field at full precision), the CasADi,
Python and package versions, a digest of the source files that shape the NLP (the planner package, the
estimator's top-level modules, the learned correction's weights and the env bookkeeping) and :data:`FORMAT`.
An edit of the model code or a retrained correction therefore never loads a stale NLP.

Safety: an entry is written to a temporary file in the cache directory and renamed into place
(``os.replace``, atomic), so concurrent writers never leave a half-written entry; each entry ends with a
trailer (magic and payload size) and starts with its key, checked before and after CasADi reads it. An
entry that is truncated, foreign or unreadable is rebuilt and replaced (a warning is logged), never a
crash; a cache directory that cannot be written is skipped with a warning. At most :data:`MAX_ENTRIES`
entries are kept (least recently used removed first); each is about 85 MB for the default 40 intervals.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import casadi as ca

__all__ = ["ENV_VAR", "FORMAT", "MAX_ENTRIES", "cache_dir", "cache_key", "load_or_build", "origin"]

logger = logging.getLogger(__name__)

#: Environment variable relocating (a directory) or disabling (``off``/``0``/``false``/``no``/empty) the cache.
ENV_VAR = "WHEELLOADER_NLP_CACHE"
#: Version of the entry layout; bump it when what :func:`load_or_build` stores changes.
FORMAT = 1
#: Entries kept in the cache directory; older ones (by last use) are removed.
MAX_ENTRIES = 8
_DISABLED = {"", "0", "off", "false", "no", "none"}
_MAGIC = b"WHEELLOADER-NLP-END"
_TRAILER = len(_MAGIC) + 20
_SUFFIX = ".casadi"
#: How each key's NLP was obtained in this process: "loaded", "built", "built (cache off)", ...
_ORIGINS: dict[tuple, str] = {}
_SOURCE_DIGEST: str | None = None


def cache_dir() -> Path | None:
    """The cache directory, or ``None`` when the cache is disabled (see the module docstring)."""
    value = os.environ.get(ENV_VAR)
    if value is not None:
        if value.strip().lower() in _DISABLED:
            return None
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME")
    root = Path(base).expanduser() if base and Path(base).is_absolute() else Path.home() / ".cache"
    return root / "wheelloader" / "nlp"


def _source_digest() -> str:
    """SHA-256 over the source files that shape the NLP (computed once per process)."""
    global _SOURCE_DIGEST
    if _SOURCE_DIGEST is None:
        import wheelloader.envs.bookkeeping as bookkeeping
        import wheelloader.estimator as estimator

        planner_dir = Path(__file__).resolve().parent
        estimator_dir = Path(estimator.__file__).resolve().parent
        # the learned correction's shipped weights shape the "fee-learned" NLP
        files = (sorted(planner_dir.glob("*.py")) + sorted(estimator_dir.glob("*.py"))
                 + sorted(estimator_dir.glob("learned_weights/*.json")))
        files.append(Path(bookkeeping.__file__).resolve())
        digest = hashlib.sha256()
        for path in files:
            digest.update(path.name.encode())
            digest.update(path.read_bytes())
        _SOURCE_DIGEST = digest.hexdigest()
    return _SOURCE_DIGEST


def cache_key(bucket: Any, loader: Any, options: Any) -> str:
    """The entry name of an NLP: a SHA-256 hex digest of everything that shapes it (module docstring)."""
    try:
        from importlib.metadata import version

        package = version("wheelloader")
    except Exception:  # noqa: BLE001 - a source checkout without metadata
        package = "unknown"
    text = json.dumps({"format": FORMAT, "casadi": ca.__version__, "python": platform.python_version(),
                       "machine": platform.machine(), "package": package, "source": _source_digest(),
                       "settings": repr((bucket, loader, options))}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def origin(bucket: Any, loader: Any, options: Any) -> str | None:
    """How this process obtained the NLP of these settings: ``"loaded from <path>"``, ``"built"``,
    ``"built and cached in <path>"``, ``"built (cache off)"``; ``None`` if it was not built here."""
    return _ORIGINS.get((bucket, loader, options))


def load_or_build(bucket: Any, loader: Any, options: Any, build: Callable[[Any, Any, Any], tuple]) -> tuple:
    """The NLP of these settings from the cache, or ``build(bucket, loader, options)`` stored in it.

    Parameters
    ----------
    bucket, loader, options
        The settings (hashable dataclasses) the NLP is built for.
    build : callable
        Returns ``(problem, {"forces": Function, ...}, layout)``: the NLP as a Function ``(x, p) -> (f, g)``
        and its helper Functions (plain CasADi Functions, serialisable; the solver is made from them).

    Returns
    -------
    tuple
        What ``build`` returns, possibly read back from the cache.
    """
    settings = (bucket, loader, options)
    directory = cache_dir()
    if directory is None:
        _ORIGINS[settings] = "built (cache off)"
        return build(bucket, loader, options)
    key = cache_key(bucket, loader, options)
    path = directory / f"nlp-{key[:40]}{_SUFFIX}"
    if path.exists():
        try:
            result = _read(path, key)
        except Exception as exc:  # noqa: BLE001 - any unreadable entry is rebuilt, never a crash
            logger.warning("NLP cache entry %s is unreadable (%s); rebuilding it", path, exc)
        else:
            _touch(path)
            _ORIGINS[settings] = f"loaded from {path}"
            return result
    result = build(bucket, loader, options)
    try:
        _write(path, key, result)
    except Exception as exc:  # noqa: BLE001 - a cache that cannot be written only costs time
        logger.warning("could not write the NLP cache entry %s (%s); set %s=off to skip the cache",
                       path, exc, ENV_VAR)
        _ORIGINS[settings] = "built"
    else:
        _ORIGINS[settings] = f"built and cached in {path}"
        _prune(directory)
    return result


def _write(path: Path, key: str, result: tuple) -> None:
    solver, functions, layout = result
    header = json.dumps({"key": key, "layout": {"ng": int(layout["ng"]), "ineq": [layout["ineq"].start,
                                                                                 layout["ineq"].stop],
                                                 "fill_end": int(layout["fill_end"]),
                                                 **({"kept_end": int(layout["kept_end"])}
                                                    if "kept_end" in layout else {})},
                         "functions": sorted(functions)})
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=".nlp-", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        serializer = ca.FileSerializer(str(tmp))
        serializer.pack(header)
        serializer.pack(solver)
        for name in sorted(functions):
            serializer.pack(functions[name])
        del serializer  # flushes and closes the file
        size = tmp.stat().st_size
        with open(tmp, "ab") as fh:  # no fsync: an entry lost or cut short by a crash fails the trailer check
            fh.write(_MAGIC + f"{size:020d}".encode())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _read(path: Path, key: str) -> tuple:
    size = path.stat().st_size
    with open(path, "rb") as fh:
        if size < _TRAILER:
            raise ValueError("too short")
        fh.seek(size - _TRAILER)
        trailer = fh.read(_TRAILER)
    if not trailer.startswith(_MAGIC) or int(trailer[len(_MAGIC):]) != size - _TRAILER:
        raise ValueError("truncated or not an NLP cache entry")
    deserializer = ca.FileDeserializer(str(path))
    header = deserializer.unpack()
    if not isinstance(header, str):
        raise ValueError("no header")
    meta = json.loads(header)
    if meta.get("key") != key:
        raise ValueError("entry of other settings")
    solver = deserializer.unpack()
    functions = {name: deserializer.unpack() for name in meta["functions"]}
    if not isinstance(solver, ca.Function) or not all(isinstance(f, ca.Function) for f in functions.values()):
        raise ValueError("unexpected content")
    lay = meta["layout"]
    layout = {"ng": int(lay["ng"]), "ineq": slice(*lay["ineq"]), "fill_end": int(lay["fill_end"])}
    if "kept_end" in lay:
        layout["kept_end"] = int(lay["kept_end"])
    if solver.n_out() != 2 or solver.size1_out(1) != layout["ng"]:
        raise ValueError("layout does not match the NLP")
    return solver, functions, layout


def _touch(path: Path) -> None:
    try:
        os.utime(path)
    except OSError:
        pass


def _prune(directory: Path) -> None:
    """Keep the :data:`MAX_ENTRIES` most recently used entries (and no stale temporary files)."""
    try:
        entries = sorted(directory.glob(f"nlp-*{_SUFFIX}"), key=lambda p: p.stat().st_mtime, reverse=True)
        for old in entries[MAX_ENTRIES:]:
            old.unlink(missing_ok=True)
        day_ago = time.time() - 86400.0
        for tmp in directory.glob(".nlp-*.tmp"):
            if tmp.stat().st_mtime < day_ago:  # left by a killed writer
                tmp.unlink(missing_ok=True)
    except OSError:
        pass
