"""One command's outputs as a unit: checked against the inputs, locked, staged, moved into place at the end.

A command declares every output up front (:meth:`OutputRun.file`, :meth:`OutputRun.directory`) with the
files and directories it reads. The declaration refuses, before any work starts:

* an output that is an input: the same real path (symlinks resolved) or the same file by hard link
  (``st_dev``/``st_ino``);
* an output inside a directory the command reads, or inside the shipped data (the checkout's ``data/``);
* an input inside an output directory;
* an output another running ``wheelloader`` holds (its lock file names the PID and the command).

:meth:`OutputRun.start` (entering the ``with`` block) locks each output with a lock file beside it
(``.NAME.wheelloader-lock``: PID and command as JSON, held with ``flock`` while the run lives, so the lock
of a run that died is taken over), and makes a staging directory beside the outputs, which also proves the
directory writable before the slow part runs. The command writes into :meth:`OutputRun.staged` paths.
Leaving the block normally moves every staged output into place (``os.replace``; a directory output is
merged into an existing one file by file); leaving it by an exception (an error, Ctrl-C) removes the
staging directory, so nothing is written and every file that existed before is as it was. Ctrl-C during
the final moves or the clean-up (microseconds) is held until they finish.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import stat
import sys
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

try:  # POSIX; elsewhere the lock file still names its owner but a dead owner's lock is not detected
    import fcntl
except ImportError:  # pragma: no cover
    fcntl = None  # type: ignore[assignment]

#: Suffix of the lock file beside each output (``.NAME`` + this).
LOCK_SUFFIX = ".wheelloader-lock"
#: Prefix of the staging directories made beside the outputs.
STAGE_PREFIX = ".wheelloader-stage-"


def shipped_data_dir() -> Path | None:
    """The ``data/`` directory of the source checkout this package runs from (None for an installed wheel)."""
    root = Path(__file__).resolve().parents[3]
    data = root / "data"
    return data if (root / "pyproject.toml").is_file() and data.is_dir() else None


def _error(message: str) -> Exception:
    from wheelloader.estimator import ParameterError

    return ParameterError(message)


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def _identity(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


#: Set by :func:`command_scope` while a command runs: after its outputs are in place, Ctrl-C stays held.
_SCOPE = {"active": False}


def _hold(signum: int, frame: Any) -> None:
    """A SIGINT handler that does nothing: the work it would interrupt must complete."""


@contextlib.contextmanager
def held_interrupts(keep: bool = False) -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) during the block; a signal that arrived is ignored (the block completes). With
    ``keep`` the hold stays after the block (until :func:`command_scope` ends)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, _hold)
    try:
        yield
    finally:
        if not keep:
            # a handler installed outside Python reads as None: Python's own (KeyboardInterrupt) comes back,
            # never the OS default, which would end the process by the signal instead of exit 130
            signal.signal(signal.SIGINT, previous if previous is not None else signal.default_int_handler)


@contextlib.contextmanager
def command_scope(program: bool) -> Iterator[None]:
    """One command of ``main()``: once its outputs are moved into place the command is complete, so Ctrl-C
    is held until it returns (it would report an interrupt with the outputs written). When ``program`` (the
    console script) Ctrl-C is then ignored through the interpreter's exit, whose clean-up restores the OS
    default (which would end the process by the signal, after it finished); in-process the handler before
    the command comes back."""
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.getsignal(signal.SIGINT) if main_thread else None
    _SCOPE["active"] = main_thread
    try:
        yield
    finally:
        _SCOPE["active"] = False
        if main_thread and program:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        elif previous is not None:
            signal.signal(signal.SIGINT, previous)


def check_input_files(paths: Iterable[tuple[str, str | Path | None]]) -> None:
    """Refuse inputs that exist but are not regular files or directories (a FIFO would block the read,
    a device never ends)."""
    for flag, value in paths:
        if value is None:
            continue
        try:
            mode = Path(value).stat().st_mode
        except OSError:
            continue  # missing files are reported by the reader, with its own message
        if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
            raise _error(f"{flag} {value} is not a regular file (a FIFO, socket or device); give a file")


class _Lock:
    """An exclusive lock on one output path (a lock file beside it, held with ``flock``)."""

    def __init__(self, target: Path, command: str) -> None:
        self.target = target
        self.path = target.with_name(f".{target.name}{LOCK_SUFFIX}")
        self.command = command
        self.fd: int | None = None

    def holder(self) -> dict[str, Any]:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError, RecursionError):
            return {}
        return data if isinstance(data, dict) else {}

    def acquire(self, stage: Path | None) -> None:
        for _ in range(5):
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                held = self.holder()
                raise _error(f"output {self.target} is in use by another wheelloader run (PID {held.get('pid', '?')}: "
                             f"{held.get('command', '?')}, since {held.get('started', '?')}); wait for it to finish "
                             "or choose another output") from None
            if _identity(self.path) != (os.fstat(fd).st_dev, os.fstat(fd).st_ino):
                os.close(fd)  # the file was removed by its previous owner between open and flock: try again
                continue
            self._clean_after_dead_owner()
            os.ftruncate(fd, 0)
            info = {"pid": os.getpid(), "command": self.command, "started": time.strftime("%Y-%m-%d %H:%M:%S"),
                    "stage": None if stage is None else str(stage)}
            os.write(fd, (json.dumps(info) + "\n").encode())
            self.fd = fd
            return
        raise _error(f"could not lock output {self.target} (its lock file {self.path} keeps changing)")

    def _clean_after_dead_owner(self) -> None:
        """Remove the staging directory a run that died (SIGKILL, power loss) left beside this output."""
        stage = self.holder().get("stage")
        if isinstance(stage, str):
            old = Path(stage)
            if old.name.startswith(STAGE_PREFIX) and old.parent == self.target.parent and old.is_dir():
                shutil.rmtree(old, ignore_errors=True)

    def release(self) -> None:
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self.fd)
        self.fd = None


class OutputRun:
    """The outputs of one command run (see the module docstring).

    Parameters
    ----------
    command : str
        What the lock files name (default: this process's command line).
    force : bool
        Whether existing outputs may be replaced.
    inputs : iterable of path or None
        Files the command reads.
    input_dirs : iterable of path or None
        Directories the command reads as a whole (nothing is written inside them).
    allow_shipped : bool
        Whether outputs may go into the checkout's ``data/`` (only ``dem reference``, which regenerates it).
    """

    def __init__(self, command: str | None = None, force: bool = False, inputs: Iterable[str | Path | None] = (),
                 input_dirs: Iterable[str | Path | None] = (), allow_shipped: bool = False) -> None:
        self.command = command or "wheelloader " + " ".join(sys.argv[1:])
        self.force = force
        self.inputs = [Path(p) for p in inputs if p is not None]
        self.input_dirs = [Path(p).resolve() for p in input_dirs if p is not None]
        shipped = None if allow_shipped else shipped_data_dir()
        self.protected = [] if shipped is None else [shipped.resolve()]
        self._real_inputs = {p.resolve() for p in self.inputs}
        self._input_ids = {i for i in (_identity(p) for p in self.inputs) if i is not None}
        self.outputs: list[tuple[Path, str, bool]] = []  # (what is moved into place, flag, is a directory)
        self._below: dict[Path, Path] = {}  # a directory output -> its part below the moved one
        self._stages: dict[Path, Path] = {}  # parent (resolved) -> staging directory
        self._locks: list[_Lock] = []
        self._started = False

    # ------------------------------------------------------------------ declaring
    def _check_common(self, flag: str, path: Path) -> Path:
        real = path.resolve()
        if real in self._real_inputs or (_identity(path) is not None and _identity(path) in self._input_ids):
            raise _error(f"{flag} {path} is one of the input files; choose another name")
        for folder in self.input_dirs:
            if _inside(real, folder):
                raise _error(f"{flag} {path} is inside the input directory {folder}; write elsewhere")
        for folder in self.protected:
            if _inside(real, folder):
                raise _error(f"{flag} {path} is inside the shipped data directory {folder}; write elsewhere")
        for other, other_flag, _ in self.outputs:
            if other.resolve() == real:
                raise _error(f"output {path} is given twice ({other_flag} and {flag}); choose different names")
        if not path.parent.is_dir():
            raise _error(f"{flag}: output directory {path.parent} does not exist")
        return real

    def file(self, flag: str, value: str | Path | None) -> Path | None:
        """Declare an output file (``None``: not requested); return its final path."""
        if value is None:
            return None
        path = Path(value)
        if path.name in ("", ".", ".."):
            raise _error(f"{flag} {str(value)!r} is not a file name")
        if path.is_dir():
            raise _error(f"{flag} {path} is a directory; give a file name")
        if path.exists() and not stat.S_ISREG(path.stat().st_mode):
            raise _error(f"{flag} {path} is not a regular file; give a file name")
        self._check_common(flag, path)
        if path.exists() and not self.force:
            raise _error(f"output {path} exists; pass --force to replace it")
        self.outputs.append((path, flag, False))
        return path

    def directory(self, flag: str, value: str | Path, fresh: bool = True) -> Path:
        """Declare an output directory; return its final path.

        With ``fresh`` an existing non-empty ``NAME`` is kept and ``NAME-2``, ``NAME-3``, ... is used
        instead; otherwise the outputs are merged into it (files of the same name replaced).
        """
        path = Path(value)
        if path.name in ("", ".", ".."):  # "." or "..": the folder by its own name
            path = Path(os.path.abspath(path))
            if not path.name:
                raise _error(f"{flag} {str(value)!r} is not a directory an output can go to")
        if path.exists() and not path.is_dir():
            raise _error(f"output directory {path} exists and is not a directory; choose another name")
        if fresh and path.is_dir() and any(path.iterdir()):
            k = 2
            while path.with_name(f"{path.name}-{k}").exists():
                k += 1
            path = path.with_name(f"{path.name}-{k}")
        top = path  # missing parents are made in the staging directory too, and moved with it
        while not top.parent.exists():
            top = top.parent
        self._check_common(flag, top)
        for p in self._real_inputs:
            if _inside(p, path.resolve()):
                raise _error(f"{flag} {path} holds the input {p}; write elsewhere")
        self.outputs.append((top, flag, True))
        self._below[path] = path.relative_to(top)
        return path

    # ------------------------------------------------------------------ running
    def staged(self, final: str | Path) -> Path:
        """Where the command writes the declared output ``final`` while it runs."""
        if not self._started:
            raise RuntimeError("OutputRun.staged() before start()")
        final = Path(final)
        for path, below in self._below.items():
            if final == path:
                top = path.parents[len(below.parts) - 1] if below.parts else path
                return self._stages[top.parent.resolve()] / top.name / below
        return self._stages[final.parent.resolve()] / final.name

    def start(self) -> OutputRun:
        """Lock every output and make the staging directories (an unwritable directory fails here)."""
        try:
            for path, flag, _ in self.outputs:
                parent = path.parent.resolve()
                try:
                    if parent not in self._stages:
                        self._stages[parent] = Path(tempfile.mkdtemp(prefix=STAGE_PREFIX, dir=parent))
                    lock = _Lock(path, self.command)
                    lock.acquire(self._stages[parent])
                except OSError as exc:
                    raise _error(f"{flag}: cannot write in {path.parent} ({exc.strerror or exc})") from None
                self._locks.append(lock)
        except BaseException:
            self.abort()
            raise
        self._started = True
        for path in self._below:
            self.staged(path).mkdir(parents=True, exist_ok=True)
        return self

    def commit(self) -> None:
        """Move every staged output into place, then remove the staging directories and the locks."""
        with held_interrupts(keep=_SCOPE["active"]):
            try:
                for path, _, is_dir in self.outputs:
                    staged = self.staged(path)
                    if not staged.exists():
                        continue  # declared but not produced (e.g. an optional figure the run skipped)
                    if is_dir and path.is_dir():
                        _merge(staged, path)
                    else:
                        os.replace(staged, path)
            finally:
                self._clean()

    def abort(self) -> None:
        """Remove everything staged and release the locks; the outputs are as they were before the run."""
        with held_interrupts():
            self._clean()

    def _clean(self) -> None:
        for stage in self._stages.values():
            shutil.rmtree(stage, ignore_errors=True)
        self._stages.clear()
        for lock in self._locks:
            lock.release()
        self._locks.clear()
        self._started = False

    def __enter__(self) -> OutputRun:
        return self.start()

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


def _merge(source: Path, target: Path) -> None:
    """Move the tree ``source`` into the existing directory ``target`` (same-named files replaced)."""
    for entry in sorted(source.iterdir()):
        dest = target / entry.name
        if entry.is_dir() and dest.is_dir():
            _merge(entry, dest)
        else:
            if dest.is_dir():
                shutil.rmtree(dest)
            os.replace(entry, dest)
