"""Plans solved side by side in one process: each thread plans in its own *lane*.

CasADi lets go of Python's global interpreter lock while IPOPT runs, so threads can solve at the same time. An
NLP (its expressions and derivatives, ~150 MB for 40 intervals) is built once and shared by the lanes; each lane
gets its own IPOPT solver of it (made from the first lane's derivative functions, no new differentiation, so its
iterates are bit-identical), with its own iteration callback and statistics, and its own warm start in each
:class:`~wheelloader.planner.TrajectoryOptimizer`. The lane of a thread is 0 until :func:`lane` says otherwise.
Ipopt (3.14 and later; CasADi 3.8 ships 3.14.19) serialises its calls into MUMPS itself, which is not
thread-safe (coin-or/Ipopt#733).

A lane may carry a cancel event: once it is set, every IPOPT solve of that lane stops at its next iteration
(the iteration callback asks IPOPT to stop), e.g. when the main thread got a Ctrl-C.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

from wheelloader.estimator import PlanningError
from wheelloader.estimator.checks import check_int

__all__ = ["cancelled", "current", "lane"]

_LOCAL = threading.local()


def current() -> int:
    """The lane of the calling thread (0 unless :func:`lane` set another)."""
    return getattr(_LOCAL, "lane", 0)


def cancelled() -> bool:
    """Whether the calling thread's lane has been cancelled (its cancel event is set)."""
    event = getattr(_LOCAL, "cancel", None)
    return event is not None and event.is_set()


@contextmanager
def lane(number: int, cancel: threading.Event | None = None) -> Iterator[int]:
    """Plan in lane ``number`` in this thread while the block runs (two threads that solve at the same time must
    be in different lanes); with ``cancel``, its solves stop once the event is set."""
    number = check_int("lane", number, minimum=0, error=PlanningError)
    if cancel is not None and not isinstance(cancel, threading.Event):
        raise PlanningError(f"cancel must be a threading.Event or None, got {type(cancel).__name__}")
    previous = (current(), getattr(_LOCAL, "cancel", None))
    _LOCAL.lane, _LOCAL.cancel = number, cancel
    try:
        yield number
    finally:
        _LOCAL.lane, _LOCAL.cancel = previous
