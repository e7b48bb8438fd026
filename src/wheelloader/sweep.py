"""One sweep runner: independent units of work run serially or as Ray tasks, results in submission order.

A sweep is a list of :class:`Unit` (a picklable callable and its keyword arguments). :func:`run_sweep`
runs them

* ``"off"``: one after the other in this process (no Ray needed);
* ``"local"``: as Ray tasks on this machine (``ray.init()``, one task per free CPU);
* an address, ``"auto"`` (the cluster this machine belongs to, started with ``ray start``) or
  ``"ray://HOST:10001"`` (Ray Client): as Ray tasks on that cluster.

Whatever ran them, the values come back in submission order, so a caller that builds its table from
them writes the same table. A unit that raises is run once more (``retries=1``); if it fails again the
sweep goes on with the others and reports it in :attr:`SweepResult.failures` with the error and the
traceback's last lines, never dropping it silently (:meth:`SweepResult.values_or_raise` raises
:class:`SweepError` naming every failed unit). ``on_result`` is called in this process as each unit
finishes (in completion order), which is where resumable callers write their files: an interrupted
sweep keeps what was finished. Progress lines (units done / total, elapsed time, ETA) go to ``progress``
when given (e.g. ``print``), else to the ``wheelloader.sweep`` logger at INFO (retries at WARNING).

Ray is an optional extra (``pip install -e ".[scale]"``); it is imported only when a Ray mode runs, so
the core install never imports it. On a cluster every node needs the same environment (``wheelloader``
and its extras installed); units and results travel pickled (``cloudpickle``), so a unit's callable must
be importable on the workers (a function of an installed module) or defined in the driver's script.
"""

from __future__ import annotations

import logging
import math
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from wheelloader.estimator import ParameterError, WheelloaderError
from wheelloader.ray_mode import LOCAL, OFF, add_ray_arguments, default_ray_mode, parse_ray_mode, ray_available

__all__ = ["OFF", "LOCAL", "Unit", "UnitFailure", "SweepError", "SweepResult", "add_ray_arguments",
           "default_ray_mode", "format_duration", "parse_ray_mode", "ray_available", "run_sweep"]

logger = logging.getLogger("wheelloader.sweep")


@dataclass(frozen=True)
class Unit:
    """One unit of work: ``fn(**kwargs)``.

    Parameters
    ----------
    fn : callable
        A picklable callable (a module-level function; ``functools.partial`` of one works too).
    kwargs : mapping
        Its keyword arguments (picklable).
    label : str
        Names the unit in progress lines and failure reports.
    num_cpus : float
        CPUs one Ray task of this unit reserves (e.g. a multi-threaded simulation); ignored when serial.
    """

    fn: Callable[..., Any]
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""
    num_cpus: float = 1.0

    def __post_init__(self) -> None:
        if not callable(self.fn):
            raise ParameterError(f"Unit.fn must be callable, got {self.fn!r}")
        if not (isinstance(self.num_cpus, int | float) and self.num_cpus > 0 and math.isfinite(self.num_cpus)):
            raise ParameterError(f"Unit.num_cpus must be a positive number, got {self.num_cpus!r}")


@dataclass(frozen=True)
class UnitFailure:
    """A unit that failed on every attempt: its position, label, attempts and the last error."""

    index: int
    label: str
    attempts: int
    error: str
    traceback: str = ""

    def __str__(self) -> str:
        return f"unit {self.index} ({self.label or 'unlabelled'}) failed {self.attempts}x: {self.error}"


class SweepError(WheelloaderError):
    """Units of a sweep failed on every attempt; :attr:`failures` names them."""

    def __init__(self, failures: Sequence[UnitFailure], total: int) -> None:
        self.failures = list(failures)
        lines = "; ".join(str(f) for f in self.failures)
        super().__init__(f"{len(self.failures)} of {total} sweep units failed: {lines}")


@dataclass
class SweepResult:
    """What a sweep gave: values in submission order (``None`` where a unit failed) and the failures."""

    values: list[Any]
    failures: list[UnitFailure]
    unit_seconds: list[float | None]
    wall_s: float
    mode: str
    workers: int
    retried: list[int] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when every unit succeeded (after retries)."""
        return not self.failures

    def values_or_raise(self) -> list[Any]:
        """The values, or :class:`SweepError` naming every failed unit."""
        if self.failures:
            raise SweepError(self.failures, len(self.values))
        return self.values

    def summary(self) -> dict[str, Any]:
        """JSON-able record: mode, workers, units, failures, retried units, wall time and unit time."""
        busy = sum(s for s in self.unit_seconds if s is not None)
        return {"mode": self.mode, "workers": self.workers, "units": len(self.values),
                "failed": [{"index": f.index, "label": f.label, "attempts": f.attempts, "error": f.error}
                           for f in self.failures],
                "retried": list(self.retried), "wall_s": self.wall_s, "unit_seconds_total": busy}


# ------------------------------------------------------------------ progress
def format_duration(seconds: float) -> str:
    """``"42 s"``, ``"3 min 05 s"``, ``"1 h 02 min"``."""
    if not math.isfinite(seconds):
        return "?"
    s = int(round(max(seconds, 0.0)))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {(s % 3600) // 60:02d} min"


class _Progress:
    """Units done / total with the elapsed time and an ETA (elapsed wall time per finished unit x units
    left: with parallel workers the rate already includes the parallelism)."""

    def __init__(self, total: int, sink: Callable[[str], None] | None) -> None:
        self.total, self.done, self.sink = total, 0, sink
        self.start = time.perf_counter()

    def report(self, label: str, status: str) -> None:
        self.done += 1
        elapsed = time.perf_counter() - self.start
        left = self.total - self.done
        eta = elapsed / self.done * left
        line = (f"[{self.done}/{self.total}] {label}: {status}; elapsed {format_duration(elapsed)}, "
                f"ETA {format_duration(eta) if left else 'done'}")
        self._emit(line, logging.INFO)

    def note(self, line: str, level: int = logging.INFO) -> None:
        self._emit(line, level)

    def _emit(self, line: str, level: int) -> None:
        # with a sink the line is shown there; the logger then keeps it at DEBUG so that it is not shown twice
        if self.sink is not None:
            self.sink(line)
            logger.debug(line)
        else:
            logger.log(level, line)


def _call(fn: Callable[..., Any], kwargs: Mapping[str, Any]) -> tuple[Any, float]:
    """Run one unit and time it (the body of a Ray task and of a serial step)."""
    start = time.perf_counter()
    value = fn(**kwargs)
    return value, time.perf_counter() - start


def _error_text(exc: BaseException) -> tuple[str, str]:
    """``"Type: message"`` of the root error and the last lines of its traceback."""
    cause = getattr(exc, "cause", None)  # a RayTaskError carries the task's own exception
    root = cause if isinstance(cause, BaseException) else exc
    message = str(root).strip().splitlines()
    text = f"{type(root).__name__}: {message[0] if message else ''}".rstrip(": ")
    tb = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return text, "\n".join(tb.strip().splitlines()[-12:])


# ------------------------------------------------------------------ the runner
def run_sweep(units: Sequence[Unit], ray: str = OFF, *, ray_cpus: int | None = None, retries: int = 1,
              on_result: Callable[[int, Any], None] | None = None,
              describe: Callable[[Any], str] | None = None,
              progress: Callable[[str], None] | None = None) -> SweepResult:
    """Run ``units`` serially (``ray="off"``) or as Ray tasks; values in submission order.

    Parameters
    ----------
    units : sequence of Unit
        The work; each unit is independent of the others.
    ray : str
        ``"off"``, ``"local"``, ``"auto"`` or a cluster address (:func:`parse_ray_mode`). With Ray already
        initialised in this process (e.g. ``ray.init(num_cpus=2)`` by the caller) that session is used and
        left running; otherwise the runner starts one and shuts it down at the end.
    ray_cpus : int, optional
        ``"local"`` only: CPUs Ray may use (default: all of this machine's).
    retries : int
        Extra attempts of a unit that raised (default 1: run once more, then report it).
    on_result : callable, optional
        ``on_result(index, value)``, called in this process as each unit succeeds (completion order).
    describe : callable, optional
        ``describe(value) -> str``, appended to the unit's progress line.
    progress : callable, optional
        Receives each progress line (e.g. ``print``); they also go to the ``wheelloader.sweep`` logger.

    Returns
    -------
    SweepResult
        ``values`` in submission order (``None`` for failed units), ``failures`` with their errors.
    """
    units = list(units)
    for k, unit in enumerate(units):
        if not isinstance(unit, Unit):
            raise ParameterError(f"sweep unit {k} must be a wheelloader.sweep.Unit, got {type(unit).__name__}")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ParameterError(f"retries must be an int >= 0, got {retries!r}")
    try:
        mode = parse_ray_mode(ray)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    if ray_cpus is not None and (isinstance(ray_cpus, bool) or not isinstance(ray_cpus, int) or ray_cpus < 1):
        raise ParameterError(f"ray_cpus must be an int >= 1, got {ray_cpus!r}")
    if ray_cpus is not None and mode not in (OFF, LOCAL):
        raise ParameterError(f"ray_cpus (--ray-cpus) applies to --ray local only; a cluster ({mode}) has its own "
                             "CPUs: set them with 'ray start --num-cpus'")
    if mode == OFF:
        return _run_serial(units, retries, on_result, describe, progress)
    return _run_ray(units, mode, ray_cpus, retries, on_result, describe, progress)


def _status(value: Any, seconds: float, describe: Callable[[Any], str] | None, attempt: int) -> str:
    text = f"done in {format_duration(seconds)}"
    if attempt > 1:
        text += f" (attempt {attempt})"
    return text + (f", {describe(value)}" if describe is not None else "")


def _run_serial(units: list[Unit], retries: int, on_result: Callable[[int, Any], None] | None,
                describe: Callable[[Any], str] | None, progress: Callable[[str], None] | None) -> SweepResult:
    start = time.perf_counter()
    bar = _Progress(len(units), progress)
    values: list[Any] = [None] * len(units)
    seconds: list[float | None] = [None] * len(units)
    failures: list[UnitFailure] = []
    retried: list[int] = []
    for k, unit in enumerate(units):
        for attempt in range(1, retries + 2):
            try:
                value, secs = _call(unit.fn, unit.kwargs)
            except Exception as exc:  # noqa: BLE001 - every failure is reported, none is lost
                error, tb = _error_text(exc)
                if attempt <= retries:
                    retried.append(k)
                    bar.note(f"{unit.label or f'unit {k}'}: attempt {attempt} failed ({error}); retrying",
                             logging.WARNING)
                    continue
                failures.append(UnitFailure(k, unit.label, attempt, error, tb))
                bar.report(unit.label or f"unit {k}", f"FAILED after {attempt} attempts: {error}")
                break
            values[k], seconds[k] = value, secs
            if on_result is not None:
                on_result(k, value)
            bar.report(unit.label or f"unit {k}", _status(value, secs, describe, attempt))
            break
    return SweepResult(values, failures, seconds, time.perf_counter() - start, OFF, 1, retried)


def _run_ray(units: list[Unit], mode: str, ray_cpus: int | None, retries: int,
             on_result: Callable[[int, Any], None] | None, describe: Callable[[Any], str] | None,
             progress: Callable[[str], None] | None) -> SweepResult:
    try:
        import ray
    except ImportError as exc:
        raise ParameterError(f"--ray {mode} needs Ray: pip install -e \".[scale]\" (or run with --ray off)") from exc
    start = time.perf_counter()
    started_here = False
    if not ray.is_initialized():
        if mode == LOCAL:
            ray.init(num_cpus=ray_cpus, include_dashboard=False, logging_level=logging.WARNING)
        else:
            ray.init(address=mode, logging_level=logging.WARNING)
        started_here = True
    try:
        workers = int(ray.cluster_resources().get("CPU", 1))
        task = ray.remote(_call)
        bar = _Progress(len(units), progress)
        bar.note(f"{len(units)} units as Ray tasks on {workers} CPUs ({mode if mode != LOCAL else 'this machine'})")
        values: list[Any] = [None] * len(units)
        seconds: list[float | None] = [None] * len(units)
        failures: list[UnitFailure] = []
        retried: list[int] = []

        def submit(k: int) -> Any:
            unit = units[k]
            # retries are counted here, not by Ray (max_retries=0), so that "retried once" is what happens
            return task.options(num_cpus=unit.num_cpus, max_retries=0, retry_exceptions=False).remote(
                unit.fn, unit.kwargs)

        pending = {submit(k): (k, 1) for k in range(len(units))}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            ref = ready[0]
            k, attempt = pending.pop(ref)
            unit = units[k]
            try:
                value, secs = ray.get(ref)
            except Exception as exc:  # noqa: BLE001 - task errors, worker crashes: all reported
                error, tb = _error_text(exc)
                if attempt <= retries:
                    retried.append(k)
                    bar.note(f"{unit.label or f'unit {k}'}: attempt {attempt} failed ({error}); retrying",
                             logging.WARNING)
                    pending[submit(k)] = (k, attempt + 1)
                    continue
                failures.append(UnitFailure(k, unit.label, attempt, error, tb))
                bar.report(unit.label or f"unit {k}", f"FAILED after {attempt} attempts: {error}")
                continue
            values[k], seconds[k] = value, secs
            if on_result is not None:
                on_result(k, value)
            bar.report(unit.label or f"unit {k}", _status(value, secs, describe, attempt))
        failures.sort(key=lambda f: f.index)
        return SweepResult(values, failures, seconds, time.perf_counter() - start,
                           f"ray {mode}", workers, sorted(retried))
    finally:
        if started_here:
            ray.shutdown()
