"""Ctrl-C during an IPOPT solve: never swallowed, never recorded as a plan.

CasADi catches a ``KeyboardInterrupt`` raised while IPOPT runs (it prints ``KeyboardInterruptException``
and the solve returns ``NonIpopt_Exception_Thrown``), so without help an interrupted solve comes back as an
ordinary, unconverged iterate that a caller may keep. :func:`guarded` wraps one solver call: it installs a
SIGINT handler that records the signal before passing it on to the handler it replaced (Python's default
raises ``KeyboardInterrupt``, which makes IPOPT stop at once), and after the call re-raises
``KeyboardInterrupt`` if a signal arrived. Outside the main thread (where no handler can be installed) the
call runs unchanged.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T")


class _Recorder:
    """A SIGINT handler that remembers it fired, then calls the handler it replaced."""

    def __init__(self, previous: Any) -> None:
        self.previous = previous
        self.fired = False

    def __call__(self, signum: int, frame: Any) -> None:
        self.fired = True
        if callable(self.previous):
            self.previous(signum, frame)
        elif self.previous == signal.SIG_DFL:  # pragma: no cover - a program that asked for the OS default
            raise KeyboardInterrupt
        # SIG_IGN: the program ignores Ctrl-C; only the record remains (and is re-raised after the solve)


def guarded(call: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``call(*args, **kwargs)``, with a SIGINT during it re-raised as ``KeyboardInterrupt`` afterwards.

    Raises
    ------
    KeyboardInterrupt
        SIGINT arrived during the call, whether or not the solver swallowed the exception.
    """
    if threading.current_thread() is not threading.main_thread():
        return call(*args, **kwargs)
    previous = signal.getsignal(signal.SIGINT)
    if previous is None or previous == signal.SIG_IGN:  # installed outside Python, or Ctrl-C is ignored
        return call(*args, **kwargs)
    recorder = _Recorder(previous)
    signal.signal(signal.SIGINT, recorder)
    try:
        result = call(*args, **kwargs)
    finally:
        signal.signal(signal.SIGINT, previous)
    if recorder.fired:
        raise KeyboardInterrupt("interrupted during an IPOPT solve")
    return result
