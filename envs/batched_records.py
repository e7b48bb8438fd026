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
        self._ring = np.zeros((max_steps + 1, len(SAMPLE_KEYS), n))
        self._first = np.zeros((len(SAMPLE_KEYS), n))
        self._start = np.zeros(n, dtype=np.int64)
        self._open = np.zeros(n, dtype=bool)
        self._meta: list[dict[str, Any] | None] = [None] * n
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
        ring = np.zeros((size, *old.shape[1:]))
        for tick in range(max(0, self.tick - old.shape[0] + 1), self.tick + 1):
            ring[tick % size] = old[tick % old.shape[0]]
        self._ring = ring

    # ------------------------------------------------------------------ writing
    def write_step(self, columns: Sequence[np.ndarray]) -> None:
        """One step of every sub-env: the columns of :data:`SAMPLE_KEYS`, each of shape ``(n,)``."""
        self.tick += 1
        row = self._ring[self.tick % self._ring.shape[0]]
        for c, values in enumerate(columns):
            row[c] = values

    def start_cycle(self, i: int, sample: Sequence[float], **meta: Any) -> None:
        """A new cycle of sub-env ``i`` with its first sample (:data:`SAMPLE_KEYS` order); ``meta``: what its
        log needs besides the samples (soil, seed, start pile)."""
        self._first[:, i] = sample
        self._start[i] = self.tick
        self._open[i] = True
        self._meta[i] = meta

    def close(self, i: int, steps: int, reason: str, carved: np.ndarray, **energies: float) -> None:
        """Close sub-env ``i``'s open cycle of ``steps`` steps (``reason``: ``"exit"``, ``"stall"`` or ``"reset"``)
        and keep it, as the single env does (a cycle of one sample is dropped); ``carved``: the surface now."""
        if not self._open[i]:
            return
        self._open[i] = False
        if steps < 1:
            return
        meta = self._meta[i]
        start = meta["start_heights"]
        changed = np.nonzero(carved != start)[0]
        self.histories[i].add(self.record(i, steps), self.keep, reason=reason, changed=changed,
                              changed_heights=carved[changed], **meta, **energies)

    # ------------------------------------------------------------------ reading
    def is_open(self, i: int) -> bool:
        """Whether sub-env ``i`` has a cycle in progress (not ended by an exit or a stall)."""
        return bool(self._open[i])

    def record(self, i: int, steps: int) -> dict[str, np.ndarray]:
        """The arrays of sub-env ``i``'s current cycle after ``steps`` steps (:data:`RECORD_KEYS`)."""
        if steps > self._ring.shape[0] - 1:
            raise ParameterError(f"a cycle of {steps} steps does not fit the record of {self._ring.shape[0] - 1}")
        ticks = np.arange(self._start[i] + 1, self._start[i] + steps + 1) % self._ring.shape[0]
        samples = np.concatenate([self._first[:, i][None, :], self._ring[ticks, :, i]])
        out = {"t": np.arange(steps + 1) * self.dt}
        for c, key in enumerate(SAMPLE_KEYS):
            out[key] = samples[:, c].astype(np.int64) if key == "flags" else samples[:, c].copy()
        return out

    def log(self, i: int, index: int, cfg: Any, source: str) -> CycleLog:
        """Kept cycle ``index`` of sub-env ``i`` as a :class:`~wheelloader.estimator.CycleLog`."""
        entry = self.histories[i][index]
        start = entry["start_pile"]
        after = start.heights.copy()
        after[entry["changed"]] = entry["changed_heights"]
        full = {**entry, "pile": start, "pile_after": Pile(start.x0, start.spacing, after)}
        return to_cycle_log(full, cfg, source=source)
