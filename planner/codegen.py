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
Every compile and load is recorded in :data:`LOG` (what, where, the compile's CPU and wall seconds). The folder
keeps the :data:`MAX_LIBRARIES` most recently used libraries.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import casadi as ca

from . import nlp_cache

__all__ = ["FLAGS", "LOG", "MAX_LIBRARIES", "SPLIT_STATEMENTS", "compiled", "compiled_by_key", "compiler",
           "present_by_key"]

logger = logging.getLogger(__name__)

#: Compiler flags (-O1: about 3 times faster than -O0 code on the MPC's Hessian for 3 times the compile time).
FLAGS: tuple[str, ...] = ("-O1", "-shared", "-fPIC")
#: One entry per :func:`compiled` call of this process: name, digest, library path, "compiled" / "loaded" /
#: "failed: ...", and for a compile its CPU and wall seconds.
LOG: list[dict] = []
#: :func:`compiled_by_key`: statements per C function and functions per translation unit. gcc's time and memory
#: grow faster than the size of a function (the IPOPT Hessian of the demo's 40-interval NLP is one function of
#: 1.16M statements, 30 MB of C; whole, it took 7 GB to compile at -O1), so its body is cut into pieces that
#: share their intermediate values through CasADi's work vector ``w`` (the same operations in the same order).
SPLIT_STATEMENTS = 2000
SPLIT_FUNCTIONS = 10
#: Libraries kept in the cache's ``compiled`` folder (the most recently used; :func:`_prune` after each compile).
MAX_LIBRARIES = 8
#: :func:`compiled_by_key`: translation units compiled at once (at most one per CPU).
COMPILE_JOBS = 4
#: Version of the split layout (part of the library's digest). 2: the functions pass through CasADi's common
#: subexpression elimination (:func:`_without_repeats`) before their C is generated.
SPLIT_FORMAT = 2
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
    names = {key: f.name() for key, f in functions.items()}
    source = _c_source(name, functions.values())
    cc = compiler()
    entry: dict = {"name": name, "functions": list(names.values()), "source_bytes": len(source)}
    LOG.append(entry)
    if cc is None:
        return _no_compiler(entry)
    library = _library(name, [source, cc, " ".join(FLAGS), ca.__version__], entry)
    if library.exists():
        loaded = _load(names, library, entry, "loaded")
        if loaded is not None:
            return loaded
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
        _compile(source, cc, library, entry)
    except (OSError, subprocess.CalledProcessError) as exc:
        return _compile_failed(entry, exc)
    return _load(names, library, entry, "compiled")


def _c_source(name: str, functions) -> str:
    """The C of ``functions`` (an iterable of CasADi Functions) from one :class:`casadi.CodeGenerator`."""
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for function in functions:
        generator.add(function)
    return generator.dump()


def _library(name: str, parts: list[str], entry: dict) -> Path:
    """The cached library's path: ``name`` and a SHA-256 digest of ``parts`` (recorded in ``entry``)."""
    digest = hashlib.sha256("\n".join(parts).encode()).hexdigest()
    library = _directory() / f"{name}-{digest[:32]}.so"
    entry.update(digest=digest, library=str(library))
    return library


def _no_compiler(entry: dict) -> None:
    entry["status"] = "failed: no C compiler"
    logger.warning("no C compiler (%s) for the compiled planner functions: CasADi's virtual machine is used",
                   os.environ.get("CC") or "cc")


def _compile_failed(entry: dict, exc: Exception) -> None:
    detail = exc.stderr.strip().splitlines()[-1:] if isinstance(exc, subprocess.CalledProcessError) \
        and exc.stderr else [str(exc)]
    entry["status"] = f"failed: {detail[0] if detail else exc}"
    logger.warning("compiling the planner functions failed (%s): CasADi's virtual machine is used", entry["status"])


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


def compiled_by_key(key: str, names: dict[str, str], make: Callable[[], dict[str, ca.Function]],
                    name: str) -> dict[str, ca.Function] | None:
    """Large functions compiled to C once per machine, found again by ``key`` without being made.

    Like :func:`compiled`, for functions too large to generate in every process (the IPOPT derivatives of a
    full-cycle NLP: 42 MB of C, seconds to differentiate and generate): the library is named by a digest of
    ``key`` (what determines the functions, e.g. :func:`.nlp_cache.cache_key`), the compiler, its flags, the
    CasADi version and :data:`SPLIT_FORMAT`, and loaded from there when it exists; else ``make()`` gives the
    functions, their C is cut into pieces (:data:`SPLIT_STATEMENTS`) compiled one translation unit at a time,
    linked and loaded.

    Parameters
    ----------
    key : str
        Identifies the functions ``make`` returns (a change of them must change it).
    names : dict of str to str
        The CasADi name of each function, by the keys ``make`` returns.
    make : callable
        Returns the functions by the keys of ``names`` (called only when the library must be compiled).
    name : str
        Stem of the library (a plain identifier).

    Returns
    -------
    dict or None
        External Functions by the keys of ``names``; ``None`` (with a warning) when there is no C compiler or
        the compile or the load fails.
    """
    cc = compiler()
    entry: dict = {"name": name, "functions": sorted(names.values())}
    LOG.append(entry)
    if cc is None:
        return _no_compiler(entry)
    library = _library(name, _key_parts(key, cc), entry)
    if library.exists():
        loaded = _load(names, library, entry, "loaded")
        if loaded is not None:
            return loaded
    try:
        functions = make()
        source = _c_source(name, (_without_repeats(functions[key_]) for key_ in names))
        entry["source_bytes"] = len(source)
        library.parent.mkdir(parents=True, exist_ok=True)
        _compile_split(_split(source, name), cc, library, entry)
    except (OSError, ValueError, subprocess.CalledProcessError) as exc:
        return _compile_failed(entry, exc)
    return _load(names, library, entry, "compiled")


def _without_repeats(function: ca.Function) -> ca.Function:
    """``function`` (an SX Function) with CasADi's common subexpression elimination: each repeated operation on
    the same operands is computed once and its value reused, so the outputs are bit for bit the same. IPOPT's
    Hessian of the demo's 40-interval NLP goes from 1.16M to 0.83M instructions (8 s of CPU here), its C
    from 30 to 22 MB, and one evaluation in CasADi's virtual machine from 5.2 to 3.6 ms. Other Functions are
    returned as they are."""
    if not function.is_a("SXFunction"):
        return function
    symbols = function.sx_in()
    return ca.Function(function.name(), symbols, function.call(symbols), function.name_in(), function.name_out(),
                       {"cse": True})


def present_by_key(key: str, names: dict[str, str], name: str) -> dict[str, ca.Function] | None:
    """The library :func:`compiled_by_key` made for ``key`` (the same ``names`` and ``name``), loaded, if this
    machine has it; ``None`` (nothing compiled, nothing logged) when it does not or there is no C compiler."""
    cc = compiler()
    if cc is None:
        return None
    entry: dict = {"name": name, "functions": sorted(names.values())}
    library = _library(name, _key_parts(key, cc), entry)
    if not library.exists():
        return None
    LOG.append(entry)
    return _load(names, library, entry, "loaded")


def _key_parts(key: str, cc: str) -> list[str]:
    """What names :func:`compiled_by_key`'s library besides ``key``: the compiler, its flags, CasADi's version and
    the split layout."""
    return [key, cc, " ".join(FLAGS), ca.__version__, str(SPLIT_FORMAT), str(SPLIT_STATEMENTS), str(SPLIT_FUNCTIONS)]


_FUNCTION = re.compile(r"static int (casadi_f\d+)\(const casadi_real\*\* arg, casadi_real\*\* res, casadi_int\* iw, "
                       r"casadi_real\* w, int mem\) \{$")
_LOCAL = re.compile(r"\ba(\d+)\b")


def _split(source: str, stem: str) -> list[str]:
    """CasADi's generated C (:class:`casadi.CodeGenerator` of SX Functions) as translation units: the first one
    CasADi's file with each function's body replaced by calls of its pieces, the others the pieces.

    CasADi writes an SX Function as one C function: locals ``a00000, a00001, ...`` (reused), then one statement
    per instruction. Here the locals become entries of the work vector ``w`` (``a00012`` -> ``w[12]``; the
    function's work size grows to their count), and the statements go, in their order, into functions of
    :data:`SPLIT_STATEMENTS` each. Raises ValueError on a layout it does not know.
    """
    lines = source.split("\n")
    marker = "/* Configuration this file was compiled with */"
    if marker not in lines:
        raise ValueError("unknown layout of CasADi's generated C (no configuration marker)")
    # the pieces' files repeat the prelude (includes, types, CasADi's helpers made static to each file)
    prelude = [("static " + line if line.startswith("casadi_real casadi_") else line)
               for line in lines[:lines.index(marker)]]
    main: list[str] = []
    pieces: list[list[str]] = []
    work = 0
    i = 0
    while i < len(lines):
        match = _FUNCTION.match(lines[i])
        if match is None:
            main.append(lines[i])
            i += 1
            continue
        j = i + 1
        count = 0
        while lines[j].startswith("  casadi_real a"):
            count += lines[j].count(",") + 1
            j += 1
        body = []
        while lines[j] != "}":
            body.append(lines[j])
            j += 1
        if not body or body.pop() != "  return 0;" or any(not (s.startswith("  a") or s.startswith("  if (res["))
                                                               for s in body):
            raise ValueError(f"unknown layout of CasADi's generated C in {match.group(1)}")
        body = [_LOCAL.sub(lambda m: f"w[{int(m.group(1))}]", s) for s in body]
        names = []
        for k in range(0, len(body), SPLIT_STATEMENTS):
            piece = f"{stem}_{match.group(1)}_{k // SPLIT_STATEMENTS}"
            names.append(piece)
            pieces.append([f"void {piece}(const casadi_real** arg, casadi_real** res, casadi_real* w) {{",
                           *body[k:k + SPLIT_STATEMENTS], "}"])
        main.extend(f"void {piece}(const casadi_real** arg, casadi_real** res, casadi_real* w);" for piece in names)
        main.append(lines[i])
        main.extend(f"  {piece}(arg, res, w);" for piece in names)
        main.extend(["  return 0;", "}"])
        work = max(work, count)
        i = j + 1
    text = "\n".join(main)
    sizes = ("if (sz_w) *sz_w = 0;", "if (sz_w) *sz_w = 0*sizeof(casadi_real);")
    if text.count(sizes[0]) != text.count(sizes[1]) or not text.count(sizes[0]):
        raise ValueError("unknown layout of CasADi's generated C (work sizes)")
    text = text.replace(sizes[0], f"if (sz_w) *sz_w = {work};").replace(sizes[1],
                                                                       f"if (sz_w) *sz_w = {work}*sizeof(casadi_real);")
    units = [text]
    for k in range(0, len(pieces), SPLIT_FUNCTIONS):
        units.append("\n".join(prelude + [line for piece in pieces[k:k + SPLIT_FUNCTIONS] for line in piece]) + "\n")
    return units


def _compile_split(units: list[str], cc: str, library: Path, entry: dict) -> None:
    """Compile the translation units ``units`` one at a time and link them into ``library`` (renamed into place)."""
    flags = [flag for flag in FLAGS if flag != "-shared"]
    with tempfile.TemporaryDirectory(dir=library.parent) as work:
        wall, before = time.perf_counter(), os.times()
        objects = []
        commands = []
        for k, unit in enumerate(units):
            c_file = Path(work) / f"unit{k}.c"
            c_file.write_text(unit)
            objects.append(str(c_file.with_suffix(".o")))
            commands.append([cc, *flags, "-c", str(c_file), "-o", objects[-1]])
        # one compiler per CPU (at most COMPILE_JOBS): the units are independent, the link takes them in order
        jobs = max(1, min(COMPILE_JOBS, os.cpu_count() or 1, len(commands)))
        pool = ThreadPoolExecutor(jobs)
        try:
            for done in pool.map(lambda command: subprocess.run(command, capture_output=True, text=True), commands):
                done.check_returncode()
        finally:  # a failed unit or a Ctrl-C: the units not started are dropped, the running ones awaited
            pool.shutdown(wait=True, cancel_futures=True)
        out = Path(work) / library.name
        subprocess.run([cc, "-shared", *objects, "-o", str(out), "-lm"], check=True, capture_output=True, text=True)
        after = os.times()
        entry["compile_wall_seconds"] = time.perf_counter() - wall
        entry["compile_cpu_seconds"] = (after.children_user + after.children_system
                                        - before.children_user - before.children_system)
        entry["units"] = len(units)
        entry["compile_jobs"] = jobs
        os.replace(out, library)


def _load(names: dict[str, str], library: Path, entry: dict, how: str) -> dict[str, ca.Function] | None:
    try:
        loaded = {key: ca.external(casadi_name, str(library)) for key, casadi_name in names.items()}
    except RuntimeError as exc:
        entry["status"] = f"failed: cannot load {library.name} ({str(exc).splitlines()[-1] if str(exc) else exc})"
        logger.warning("%s: CasADi's virtual machine is used", entry["status"])
        return None
    entry["status"] = how
    try:
        os.utime(library)  # its last use: the pruning keeps the most recently used libraries
    except OSError:
        pass
    if how == "compiled":
        _prune(library.parent)
    return loaded


def _prune(directory: Path) -> None:
    """Keep the :data:`MAX_LIBRARIES` most recently used libraries of ``directory`` (a library for the NLP of an
    older version of the code is never loaded again). A library another process has loaded stays usable there
    (on Linux its file lives on until unmapped); a file that cannot be removed is left."""
    try:
        libraries = sorted(directory.glob("*.so"), key=lambda path: path.stat().st_mtime, reverse=True)
    except OSError:
        return
    for old in libraries[MAX_LIBRARIES:]:
        try:
            old.unlink()
        except OSError:
            pass
