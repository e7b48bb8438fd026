"""The cycle records of the batched env: what the single env's ``episode_record`` and cycle logs hold, per sub-env.

The single env appends each sample to Python lists. The batched env writes the samples of every sub-env at
once into a ring indexed by the batch's step count (one contiguous row per column and step), and keeps each
cycle's first sample (the start pose, measured at the reset) beside it. A cycle of sub-env ``i`` is then its
first sample followed by the ring rows of the steps since its reset. The ring holds ``max_episode_steps + 1``
steps, so a cycle stays readable until the step after it ended, when the env resets it (and closes it as
``"reset"``, as the single env's ``reset()`` does).

A closed cycle is copied out into a :class:`~wheelloader.envs.cycle_history.CycleHistory` per sub-env. Its
piles are kept compactly (the start surface by reference when it is the configured pile, the carved surface as
the nodes it changed) and built as :class:`~wheelloader.estimator.Pile` only when a log is asked for.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Sequence
from typing import Any

import numpy as np

from wheelloader.estimator import CycleLog, ParameterError, Pile

from .cycle_history import RECORD_KEYS, CycleHistory, to_cycle_log

__all__ = ["SAMPLE_KEYS", "BatchedCycleRecorder"]

#: Columns of the ring, in order: :data:`~wheelloader.envs.cycle_history.RECORD_KEYS` without ``t`` (which is
#: the sample index times ``dt``).
SAMPLE_KEYS: tuple[str, ...] = tuple(k for k in RECORD_KEYS if k != "t")


class BatchedCycleRecorder:
    """Samples, open cycles and kept finished cycles of ``n`` sub-envs.

    Parameters
    ----------
    n : int
        Number of sub-envs.
    max_steps : int
        The longest cycle in steps (the episode limit).
    dt : float
        Control period [s] (the ``t`` column).
    keep : int
        Finished cycles kept per sub-env.
    """

    def __init__(self, n: int, max_steps: int, dt: float, keep: int) -> None:
        self.n, self.dt, self.keep = n, dt, keep
        self.tick = 0
        # (step, column, sub-env): a step's samples are one contiguous block (written with one np.concatenate of
        # contiguous rows), a cycle's are one strided column per step. Filled now, so that the steps do not pay
        # for first touches.
        self._ring = np.full((max_steps + 1, len(SAMPLE_KEYS), n), 0.0)
        self._first = np.zeros((n, len(SAMPLE_KEYS)))
        self._start = np.zeros(n, dtype=np.int64)
        self._open = np.zeros(n, dtype=bool)
        self._meta: list[dict[str, Any] | None] = [None] * n
        self._lazy: list[tuple] = []  # (first tick, order, entry) of kept cycles whose samples are in the ring
        self._order = itertools.count()
        self.histories = [CycleHistory() for _ in range(n)]

    @property
    def capacity(self) -> int:
        """Steps the ring holds."""
        return self._ring.shape[0]

    def grow(self, max_steps: int) -> None:
        """Make room for cycles of ``max_steps`` steps, keeping what the ring holds."""
        size = max_steps + 1
        old = self._ring
        if size <= old.shape[0]:
            return
        ring = np.full((size, *old.shape[1:]), 0.0)
        for tick in range(max(0, self.tick - old.shape[0] + 1), self.tick + 1):
            ring[tick % size] = old[tick % old.shape[0]]
        self._ring = ring

    # ------------------------------------------------------------------ writing
    def write_step(self, columns: Sequence[np.ndarray]) -> None:
        """One step of every sub-env: the columns of :data:`SAMPLE_KEYS`, each of shape ``(n,)``."""
        self.tick += 1
        size = self._ring.shape[0]
        lazy = self._lazy
        while lazy and lazy[0][0] + size <= self.tick:  # its first step's row is about to be overwritten
            self._materialize(heapq.heappop(lazy)[2])
        np.concatenate(columns, out=self._ring[self.tick % size].reshape(-1))  # np.stack's values, less overhead

    def _materialize(self, entry: dict[str, Any]) -> None:
        """Copy a kept cycle's samples out of the ring (once; nothing for a dropped one)."""
        if entry["record"] is None and entry["ring"] is not None:
            start, steps, first = entry["ring"]
            entry["record"] = self._samples(start, steps, first, entry["i"])
            entry["ring"] = None

    def start_cycle(self, i: int, sample: Sequence[float], **meta: Any) -> None:
        """A new cycle of sub-env ``i`` with its first sample (:data:`SAMPLE_KEYS` order); ``meta``: what its
        log needs besides the samples (soil, seed, start pile)."""
        self._first[i] = sample
        self._start[i] = self.tick
        self._open[i] = True
        self._meta[i] = {"i": i, **meta}

    def close(self, i: int, steps: int, reason: str, carved: np.ndarray, **energies: float) -> None:
        """Close sub-env ``i``'s open cycle of ``steps`` steps (``reason``: ``"exit"``, ``"stall"`` or ``"reset"``)
        and keep it, as the single env does (a cycle of one sample is dropped); ``carved``: the surface now."""
        if not self._open[i]:
            return
        self._open[i] = False
        if steps < 1:
            return
        meta = self._meta[i]
        changed = np.nonzero(carved != meta["start_heights"])[0]
        # The samples stay in the ring until a step would overwrite them (or a log asks): most kept cycles are
        # dropped for a newer one before that, and are never copied out.
        entry = {"record": None, "ring": (int(self._start[i]), steps, self._first[i].copy()), "reason": reason,
                 "changed": changed, "changed_heights": carved[changed], **meta, **energies}
        heapq.heappush(self._lazy, (int(self._start[i]) + 1, next(self._order), entry))
        for old in self.histories[i].append(entry, self.keep):
            old["ring"] = None  # dropped: never needed

    # ------------------------------------------------------------------ reading
    def is_open(self, i: int) -> bool:
        """Whether sub-env ``i`` has a cycle in progress (not ended by an exit or a stall)."""
        return bool(self._open[i])

    def record(self, i: int, steps: int) -> dict[str, np.ndarray]:
        """The arrays of sub-env ``i``'s current cycle after ``steps`` steps (:data:`RECORD_KEYS`)."""
        return self._samples(int(self._start[i]), steps, self._first[i], i)

    def kept(self, i: int, index: int) -> dict[str, Any]:
        """Kept cycle ``index`` of sub-env ``i`` (its samples copied out of the ring if not yet)."""
        entry = self.histories[i][index]
        self._materialize(entry)
        return entry

    def _samples(self, start: int, steps: int, first: np.ndarray, i: int) -> dict[str, np.ndarray]:
        if steps > self._ring.shape[0] - 1:
            raise ParameterError(f"a cycle of {steps} steps does not fit the record of {self._ring.shape[0] - 1}")
        ticks = np.arange(start + 1, start + steps + 1) % self._ring.shape[0]
        samples = np.concatenate([first[None, :], self._ring[ticks, :, i]])
        out = {"t": np.arange(steps + 1) * self.dt}
        for c, key in enumerate(SAMPLE_KEYS):
            out[key] = samples[:, c].astype(np.int64) if key == "flags" else samples[:, c].copy()
        return out

    def log(self, i: int, index: int, cfg: Any, source: str) -> CycleLog:
        """Kept cycle ``index`` of sub-env ``i`` as a :class:`~wheelloader.estimator.CycleLog`."""
        entry = self.kept(i, index)
        start = entry["start_pile"]
        after = start.heights.copy()
        after[entry["changed"]] = entry["changed_heights"]
        full = {**entry, "pile": start, "pile_after": Pile(start.x0, start.spacing, after)}
        return to_cycle_log(full, cfg, source=source)
