"""CasADi functions as compiled C code: generated, compiled once per machine and cached on disk.

:func:`compiled` turns CasADi Functions (the derivatives a solver evaluates at every iteration) into C with
:class:`casadi.CodeGenerator`, compiles them into a shared library with the system's C compiler (``$CC``,
default ``cc``; flags :data:`FLAGS`) and loads them with :func:`casadi.external`. The compiled functions give
the same numbers as CasADi's virtual machine here (the SQP's iterates bit-identical on the MPC's re-plans,
``benchmarks/planner.py``), about 2-5 times faster to evaluate.

Cache: the library is named by a SHA-256 digest of the generated C source, the compiler, its flags and the
CasADi version, in the ``compiled`` folder of the NLP cache (:func:`.nlp_cache.cache_dir`; with the cache off,
a temporary folder for this process). A library is compiled into a temporary file and renamed into place
(atomic), so concurrent processes never load a half-written one. No C compiler, a failed compile or a library
that cannot be loaded: a warning is logged and ``None`` returned (the caller keeps CasADi's virtual machine).
Every compile and load is recorded in :data:`LOG` (what, where, the compile's CPU and wall seconds).
"""

from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca

from . import nlp_cache

__all__ = ["FLAGS", "LOG", "compiled", "compiler"]

logger = logging.getLogger(__name__)

#: Compiler flags (-O1: about 3 times faster than -O0 code on the MPC's Hessian for 3 times the compile time).
FLAGS: tuple[str, ...] = ("-O1", "-shared", "-fPIC")
#: One entry per :func:`compiled` call of this process: name, digest, library path, "compiled" / "loaded" /
#: "failed: ...", and for a compile its CPU and wall seconds.
LOG: list[dict] = []
_TEMP_DIR: Path | None = None


def compiler() -> str | None:
    """The C compiler's path (``$CC`` or ``cc``), or ``None`` when there is none."""
    return shutil.which(os.environ.get("CC") or "cc")


def _directory() -> Path:
    global _TEMP_DIR
    base = nlp_cache.cache_dir()
    if base is not None:
        return base / "compiled"
    if _TEMP_DIR is None:
        _TEMP_DIR = Path(tempfile.mkdtemp(prefix="wheelloader-compiled-"))
    return _TEMP_DIR


def compiled(functions: dict[str, ca.Function], name: str) -> dict[str, ca.Function] | None:
    """``functions`` (by any key) compiled to C, as external Functions of the same names and signatures.

    Parameters
    ----------
    functions : dict of str to casadi.Function
        What to compile (their CasADi names must differ).
    name : str
        Stem of the C file and the library (a plain identifier).

    Returns
    -------
    dict or None
        The same keys, each an external Function loaded from the cached library; ``None`` (with a warning)
        when there is no C compiler or the compile or load fails.
    """
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for function in functions.values():
        generator.add(function)
    source = generator.dump()
    cc = compiler()
    entry: dict = {"name": name, "functions": [f.name() for f in functions.values()], "source_bytes": len(source)}
    LOG.append(entry)
    if cc is None:
        entry["status"] = "failed: no C compiler"
        logger.warning("no C compiler (%s) for the compiled planner functions: CasADi's virtual machine is used",
                       os.environ.get("CC") or "cc")
        return None
    digest = hashlib.sha256("\n".join([source, cc, " ".join(FLAGS), ca.__version__]).encode()).hexdigest()
    directory = _directory()
    library = directory / f"{name}-{digest[:32]}.so"
    entry.update(digest=digest, library=str(library))
    if library.exists():
        loaded = _load(functions, library, entry, "loaded")
        if loaded is not None:
            return loaded
    try:
        directory.mkdir(parents=True, exist_ok=True)
        _compile(source, cc, library, entry)
    except (OSError, subprocess.CalledProcessError) as exc:
        detail = exc.stderr.strip().splitlines()[-1:] if isinstance(exc, subprocess.CalledProcessError) \
            and exc.stderr else [str(exc)]
        entry["status"] = f"failed: {detail[0] if detail else exc}"
        logger.warning("compiling the planner functions failed (%s): CasADi's virtual machine is used",
                       entry["status"])
        return None
    return _load(functions, library, entry, "compiled")


def _compile(source: str, cc: str, library: Path, entry: dict) -> None:
    """Compile ``source`` into ``library`` (through a temporary file in its folder, renamed into place)."""
    with tempfile.TemporaryDirectory(dir=library.parent) as work:
        c_file = Path(work) / "functions.c"
        c_file.write_text(source)
        out = Path(work) / library.name
        wall, before = time.perf_counter(), os.times()
        subprocess.run([cc, *FLAGS, str(c_file), "-o", str(out), "-lm"], check=True, capture_output=True, text=True)
        after = os.times()
        entry["compile_wall_seconds"] = time.perf_counter() - wall
        entry["compile_cpu_seconds"] = (after.children_user + after.children_system
                                        - before.children_user - before.children_system)
        os.replace(out, library)


def _load(functions: dict[str, ca.Function], library: Path, entry: dict, how: str) -> dict[str, ca.Function] | None:
    try:
        loaded = {key: ca.external(f.name(), str(library)) for key, f in functions.items()}
    except RuntimeError as exc:
        entry["status"] = f"failed: cannot load {library.name} ({str(exc).splitlines()[-1] if str(exc) else exc})"
        logger.warning("%s: CasADi's virtual machine is used", entry["status"])
        return None
    entry["status"] = how
    return loaded
