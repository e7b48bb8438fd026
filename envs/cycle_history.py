"""The finished digging cycles a :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv` keeps.

Each finished cycle is an entry (a dict): the raw per-sample arrays
(``record``), the start and carved piles, the soil, why the cycle ended
(``reason``: ``"exit"``, ``"stall"`` or ``"reset"``), the seed, the cycle
index and the cycle's energies. :func:`to_cycle_log` turns an entry into the
estimator's :class:`~wheelloader.estimator.CycleLog`.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, CycleLog, ParameterError

__all__ = ["RECORD_KEYS", "CycleHistory", "record_arrays", "to_cycle_log"]

#: Per-sample arrays of a cycle: path, measured forces, fill [m^3], noise-free plant forces, model flags.
RECORD_KEYS: tuple[str, ...] = ("t", "x", "z", "blade_angle", "F_T", "F_N", "fill", "true_F_T", "true_F_N", "flags")


def record_arrays(samples: list[tuple]) -> dict[str, np.ndarray]:
    """A cycle's samples (tuples in :data:`RECORD_KEYS` order, as the single env appends them) as one array
    per key (``flags`` as int64; the other columns are floats and stay exactly as given)."""
    columns = np.array(samples, dtype=float).reshape(len(samples), len(RECORD_KEYS))
    return {k: columns[:, c].astype(np.int64) if k == "flags" else columns[:, c].copy()
            for c, k in enumerate(RECORD_KEYS)}


class CycleHistory:
    """The last finished cycles (oldest first), each a dict; indexable and sized like a list."""

    def __init__(self) -> None:
        self._entries: list[dict[str, Any]] = []

    def add(self, record: Mapping[str, list], keep: int, **entry: Any) -> None:
        """Store a finished cycle (its ``record`` lists become arrays); keep the last ``keep`` cycles."""
        arrays = {k: np.asarray(v, dtype=np.int64 if k == "flags" else float) for k, v in record.items()}
        self.append({"record": arrays, **entry}, keep)

    def append(self, entry: dict[str, Any], keep: int) -> list[dict[str, Any]]:
        """Store a prepared entry as it is; keep the last ``keep`` cycles. Returns the entries dropped."""
        self._entries.append(entry)
        dropped = self._entries[:-keep]
        del self._entries[:-keep]
        return dropped

    def __len__(self) -> int:
        return len(self._entries)

    def __getitem__(self, index: int) -> dict[str, Any]:
        return self._entries[index]

    def __iter__(self) -> Iterator[dict[str, Any]]:
        return iter(self._entries)

    def record(self, index: int = -1) -> dict[str, np.ndarray]:
        """The raw arrays of a kept cycle."""
        if not self._entries:
            raise ParameterError("no finished cycle yet")
        return dict(self._entries[index]["record"])

    @property
    def ends(self) -> tuple[str, ...]:
        """Why each kept cycle ended (``"exit"``, ``"stall"`` or ``"reset"``), oldest first."""
        return tuple(e["reason"] for e in self._entries)


def to_cycle_log(entry: Mapping[str, Any], cfg: Any, source: str = "wheelloader.envs.BucketLoadingEnv") -> CycleLog:
    """A finished cycle as a :class:`~wheelloader.estimator.CycleLog` (measured forces; metadata: the env class
    ``source``, true soil, seed, cycle index, end reason, energies [J] and the env settings ``cfg``)."""
    rec = entry["record"]
    path = BucketPath(rec["t"], rec["x"], rec["z"], rec["blade_angle"], name=f"env cycle {entry['cycle']}")
    metadata = {
        "source": source, "true_soil": entry["soil"].to_dict(),
        "seed": entry["seed"], "cycle": entry["cycle"], "end": entry["reason"],
        "energy_soil": entry["energy_soil"], "energy_payload": entry["energy_payload"],
        "env": cfg.to_dict(),
    }
    return CycleLog(path=path, tangential=rec["F_T"], normal=rec["F_N"], pile=entry["pile"], bucket=cfg.bucket,
                    fill_volume=rec["fill"], pile_after=entry["pile_after"], metadata=metadata)
