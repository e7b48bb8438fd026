"""Saved loops: each cycle of an adaptation loop kept on disk as it finishes, read back to resume or replay.

A loop's folder holds ``cycle<k>.csv.xz`` (+ its ``.json.xz`` sidecar, :meth:`~wheelloader.estimator.CycleLog.save`;
an uncompressed ``cycle<k>.csv`` + ``.json`` is read too) for k = 1, 2, ...; each log's metadata records the SHA-256
of the path that was planned for it (``planned_path_sha256``) and the plan's record (``plan``), so that
:func:`wheelloader.loop.run_loop` can tell a saved cycle of the plan it makes now from one dug along another path
(:func:`resolve_saved_cycle`). A run's loops lie under ``ROOT/<soil>/seed<k>/<strategy>/`` (:func:`saved_loops`).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import CycleLog, SoilParams, WheelloaderError
from wheelloader.estimator.cyclelog import cycle_log_files, find_cycle_log, log_stem
from wheelloader.planner import MODEL_FALLBACK_NAME

#: The suffix :func:`save_cycle` writes (xz-compressed CSV; its sidecar ``.json.xz``).
COMPRESSED_LOG = ".csv.xz"
#: What :func:`resolve_saved_cycle` may do with a saved cycle dug along another path than the one planned now.
STALE_CHOICES: tuple[str, ...] = ("error", "redig", "keep")


def cycle_file(folder: str | Path, k: int) -> Path:
    """Where cycle ``k`` (1, 2, ...) of the loop saved in ``folder`` lies: the saved file (compressed or not) when
    there is one, else where :func:`save_cycle` writes it (``cycle<k>.csv.xz``)."""
    return find_cycle_log(folder, f"cycle{k}") or Path(folder) / f"cycle{k}{COMPRESSED_LOG}"


def load_saved_cycle(folder: str | Path | None, k: int, *, check: bool = True) -> CycleLog | None:
    """Cycle ``k`` of the loop saved in ``folder``; None without a folder or without that cycle. ``check``: as
    :meth:`CycleLog.load`'s (False for a plant's own cycles whose forces may trip its sign-convention check)."""
    if folder is None:
        return None
    saved = find_cycle_log(folder, f"cycle{k}")
    return None if saved is None else CycleLog.load(saved, check=check)


def save_cycle(folder: str | Path, k: int, log: CycleLog) -> Path:
    """Save ``log`` as cycle ``k`` of the loop in ``folder`` (made if missing), xz-compressed; a saved cycle ``k``
    (compressed or not) is replaced. Returns the CSV's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    target = log.save(folder / f"cycle{k}{COMPRESSED_LOG}", overwrite=True)
    for plain in (folder / f"cycle{k}.csv", folder / f"cycle{k}.json"):  # a replaced uncompressed one
        plain.unlink(missing_ok=True)
    return target


def saved_loops(root: str | Path) -> dict[tuple[str, str, str], list[Path]]:
    """The saved loops under ``root`` (``SOIL/seedN/STRATEGY/cycleK.csv.xz``, or ``.csv``): ``(soil, "seedN",
    strategy)`` -> the cycles' files in order.

    Raises
    ------
    WheelloaderError
        When a loop's cycles are not numbered 1..n.
    """
    found: dict[tuple[str, str, str], list[Path]] = {}
    for csv in cycle_log_files(root, "*/seed*/*/cycle*"):
        strategy, seed, soil = csv.parent.name, csv.parent.parent.name, csv.parent.parent.parent.name
        found.setdefault((soil, seed, strategy), []).append(csv)
    for key, files in found.items():
        files.sort(key=lambda p: int(log_stem(p).removeprefix("cycle")))
        numbers = [int(log_stem(p).removeprefix("cycle")) for p in files]
        if numbers != list(range(1, len(numbers) + 1)):
            raise WheelloaderError(f"{root}: loop {'/'.join(key)} has cycles {numbers}, not 1..{len(numbers)}")
    return found


def path_distance(a: Any, b: Any) -> float:
    """Largest distance [m] between the tip positions of two paths, each resampled at the other's times
    (over the shorter duration); inf when their durations differ by more than one sample."""
    ta, tb = np.asarray(a.t, dtype=float), np.asarray(b.t, dtype=float)
    step = max(float(np.median(np.diff(ta))) if ta.size > 1 else 0.0,
               float(np.median(np.diff(tb))) if tb.size > 1 else 0.0)
    if abs(ta[-1] - tb[-1]) > step + 1e-12:
        return math.inf
    t = np.union1d(ta, tb)
    t = t[t <= min(ta[-1], tb[-1])]
    dx = np.interp(t, ta, a.x) - np.interp(t, tb, b.x)
    dz = np.interp(t, ta, a.z) - np.interp(t, tb, b.z)
    return float(np.max(np.hypot(dx, dz)))


def path_digest(path: Any) -> str:
    """SHA-256 of a path's samples (t, x, z, blade angle): which plan a saved cycle was dug for."""
    h = hashlib.sha256()
    for arr in (path.t, path.x, path.z, path.blade_angle):
        h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class PlanRecord:
    """What a loop records of the plan a cycle was dug along (and saves in the cycle's metadata)."""

    ok: bool
    message: str
    seconds: float
    params: SoilParams

    def to_dict(self) -> dict[str, Any]:
        """The metadata form (``log.metadata["plan"]``)."""
        return {"ok": self.ok, "message": self.message, "seconds": self.seconds, "params": self.params.to_dict()}


@dataclass(frozen=True)
class SavedCycle:
    """What :func:`resolve_saved_cycle` decided about a saved cycle.

    Attributes
    ----------
    log : CycleLog or None
        The saved cycle to use, or None: dig the cycle.
    plan : PlanRecord
        The record of the plan the cycle was dug along.
    end : str
        The cycle record's ``end``: ``"path end"`` (dug now), ``"resumed from cache"``, or why a saved cycle of
        another plan was kept.
    kept : bool
        A saved cycle of another plan is used as the cycle dug (``stale="keep"``).
    replaced : bool
        A saved cycle of another plan is dug again (``stale="redig"``).
    """

    log: CycleLog | None
    plan: PlanRecord
    end: str
    kept: bool = False
    replaced: bool = False


def resolve_saved_cycle(log: CycleLog | None, path: Any, stale: str, plan: PlanRecord, where: str) -> SavedCycle:
    """What to do with a saved cycle (``log``; None when there is none) for the plan made now (``path``).

    A saved cycle of the same plan is resumed; one dug along another path is refused (``stale="error"``,
    naming ``where``), dug again (``"redig"``) or kept as the cycle dug (``"keep"``; the plan's record is then
    read from the log, where the loop saved it).
    """
    if log is None:
        return SavedCycle(None, plan, "path end")
    if log.metadata.get("planned_path_sha256") == path_digest(path):
        return SavedCycle(log, plan, "resumed from cache")
    if stale == "error":
        raise WheelloaderError(f"{where} was dug along another path than the one planned now (other settings, "
                               "code or machine); use another cache folder, remove it, or resume with "
                               "stale='keep' or 'redig'")
    if stale == "redig":
        return SavedCycle(None, plan, "path end", replaced=True)
    end = f"kept saved cycle (path planned now differs by {path_distance(path, log.path):.3g} m)"
    saved = log.metadata.get("plan")
    dug_name = log.metadata.get("path_name")
    if isinstance(saved, dict):
        plan = PlanRecord(bool(saved["ok"]), str(saved["message"]), float(saved["seconds"]),
                          SoilParams.from_dict(saved["params"]))
    elif dug_name is not None and dug_name != path.name:
        # the log predates plan records: what was dug tells whether its plan passed the check
        plan = replace(plan, ok=dug_name != MODEL_FALLBACK_NAME,
                       message=f"kept cycle dug along the {dug_name!r} path (its plan's record not saved)")
    else:
        end += "; its plan's record is that of the plan made now"
    return SavedCycle(log, plan, end, kept=True)
