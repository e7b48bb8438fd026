"""A planner that remembers its last outcomes: the same soil and pile are planned once per process.

The cycle-to-cycle loop plans its first cycle with the nominal soil on the untouched pile, whatever the plant
seed: ``wheelloader demo`` and the adaptation benchmark plan that same cycle once per seed and strategy. A plan
is a deterministic function of its inputs (an IPOPT iteration count, not a time budget, bounds it), so
:class:`RememberedPlanner` hands back a copy of the first outcome instead of solving again. The key is the
exact soil and pile (their floats' bits), never a rounding of them.
"""

from __future__ import annotations

import copy
import struct
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import astuple
from typing import Any

from wheelloader.estimator import Pile, SoilParams, as_soil
from wheelloader.estimator.checks import check_int

from .next_cycle import PlanOutcome

__all__ = ["RememberedPlanner"]


class RememberedPlanner:
    """``planner(params, pile) -> PlanOutcome`` with its last ``size`` outcomes kept, by exact soil and pile.

    Parameters
    ----------
    planner : callable
        A deterministic planner, e.g. :func:`functools.partial` of
        :func:`~wheelloader.planner.plan_next_cycle` without an MPC controller (an outcome with a controller
        is never kept: a controller has state).
    size : int
        Outcomes kept (least recently used dropped first).

    Notes
    -----
    Thread-safe: a call for a soil and pile that another thread is planning waits for that outcome.
    A repeated call returns a deep copy of the kept outcome (the caller may set its ``seconds``), with
    ``seconds`` the time of the look-up.
    """

    def __init__(self, planner: Callable[[Any, Pile], PlanOutcome], size: int = 4) -> None:
        if not callable(planner):
            raise TypeError(f"planner must be callable, got {type(planner).__name__}")
        self.planner = planner
        self.size = check_int("size", size, minimum=1)
        self._kept: OrderedDict[bytes, PlanOutcome] = OrderedDict()
        #: How many calls were answered from the kept outcomes.
        self.hits = 0
        # threads planning side by side (planner.lanes): one plans a soil and pile, the others wait for it
        self._lock = threading.Lock()
        self._pending: dict[bytes, threading.Event] = {}

    @staticmethod
    def key(params: SoilParams | str | dict, pile: Pile) -> bytes:
        """The bits of the soil's parameters and of the pile's grid and heights."""
        soil = astuple(as_soil(params))
        heights = pile.heights
        return (struct.pack(f"<{len(soil)}d", *soil) + struct.pack("<2dq", pile.x0, pile.spacing, heights.size)
                + heights.astype("<f8").tobytes())

    def __call__(self, params: SoilParams | str | dict, pile: Pile) -> PlanOutcome:
        tic = time.perf_counter()
        key = self.key(params, pile)
        while True:
            with self._lock:
                if key in self._kept:
                    self._kept.move_to_end(key)
                    self.hits += 1
                    outcome = copy.deepcopy(self._kept[key])
                    outcome.seconds = time.perf_counter() - tic
                    return outcome
                pending = self._pending.get(key)
                if pending is None:  # this thread plans it; another one asking meanwhile waits for its outcome
                    pending = self._pending[key] = threading.Event()
                    break
            pending.wait()
        try:
            outcome = self.planner(params, pile)
            if outcome.controller is None:
                with self._lock:
                    self._kept[key] = copy.deepcopy(outcome)
                    while len(self._kept) > self.size:
                        self._kept.popitem(last=False)
        finally:
            with self._lock:
                del self._pending[key]
            pending.set()
        return outcome
