"""Cycle records: one bucket-loading cycle as CSV + JSON sidecar.

Format (version 1)
------------------
``LOG.csv``: a header row, then one row per sample, comma-separated, SI
units. Lines starting with ``#`` are comments. Columns (order free):

=============  ======  ==========================================================
column         unit    meaning
=============  ======  ==========================================================
t              s       time, strictly increasing
x, z           m       bucket-tip position (x into the pile, z up)
blade_angle    rad     blade direction (back edge -> tip) above +x; tip-down < 0
F_T            N       measured tangential force on the blade (eq 16)
F_N            N       measured normal force on the blade (eq 17)
fill_volume    m^3     optional: soil volume in the bucket
W_load         N       optional: soil weight in the bucket
=============  ======  ==========================================================

``LOG.json`` (same stem): ``{"format": "wheelloader.cyclelog", "version": 1,
"pile": {"x": [...], "z": [...]}, "pile_after": {...} | null, "bucket":
{Bucket fields}, "metadata": {...}}``. ``pile`` is the surface when the
cycle started (depth is measured to it); ``bucket`` may list only the fields
that differ from the defaults.

A path without forces (for prediction) is the same CSV with only ``t, x, z,
blade_angle``: see :func:`load_path_csv`.

Compressed logs
---------------
``LOG.csv.xz`` + ``LOG.json.xz`` are the same two files compressed with xz (LZMA): :meth:`CycleLog.save`
writes them when the path it is given ends in ``.csv.xz``, and every reader here takes either form.
:func:`find_cycle_log` names the saved log of a stem in a folder, compressed or not, and
:func:`cycle_log_files` lists a folder's logs; :func:`log_stem` is a log's name without its suffixes.
"""

from __future__ import annotations

import csv
import hashlib
import json
import lzma
import math
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .checks import check_choice
from .errors import CycleLogError, ParameterError
from .jsonable import read_json, to_jsonable
from .kinematics import DEFAULT_SLOPE_WINDOW, ContactState, contact_state
from .machine import Bucket
from .paths import BucketPath
from .pile import Pile

FORMAT_NAME = "wheelloader.cyclelog"
FORMAT_VERSION = 1
PATH_COLUMNS = ("t", "x", "z", "blade_angle")
FORCE_COLUMNS = ("F_T", "F_N")
OPTIONAL_COLUMNS = ("fill_volume", "W_load")
#: A log whose F_N is negative in more than this share of its in-soil samples has the column flipped
#: (the most negative shipped log: 74 %; sensor offsets and the curl-out give real logs a negative share).
FLIPPED_FN_SHARE = 0.90
#: Suffix of a compressed log (and of its sidecar), and the xz preset its writer uses.
COMPRESSED_SUFFIX = ".xz"
XZ_PRESET = 6
#: The suffixes a saved cycle log may have, the compressed one (which writers choose) first.
LOG_SUFFIXES = (".csv" + COMPRESSED_SUFFIX, ".csv")


def _compressed(path: Path) -> bool:
    return path.name.endswith(COMPRESSED_SUFFIX)


def log_stem(csv_path: str | Path) -> str:
    """A log's name without ``.csv`` or ``.csv.xz`` (``cycle3.csv.xz`` -> ``cycle3``)."""
    name = Path(csv_path).name
    for suffix in LOG_SUFFIXES:
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return Path(name).stem


def sidecar_path(csv_path: str | Path) -> Path:
    """The JSON sidecar of a log: ``LOG.json`` beside ``LOG.csv``, ``LOG.json.xz`` beside ``LOG.csv.xz``."""
    csv_path = Path(csv_path)
    if _compressed(csv_path):
        return csv_path.with_name(log_stem(csv_path) + ".json" + COMPRESSED_SUFFIX)
    return csv_path.with_suffix(".json")


def find_cycle_log(folder: str | Path, stem: str) -> Path | None:
    """The saved log ``stem`` in ``folder`` (``stem.csv.xz`` or ``stem.csv``), or None when there is neither."""
    for suffix in LOG_SUFFIXES:
        candidate = Path(folder) / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def cycle_log_files(folder: str | Path, pattern: str = "*") -> list[Path]:
    """The logs in ``folder`` whose stem matches the glob ``pattern`` (may hold ``/``), compressed or not,
    sorted by path."""
    found = {p for suffix in LOG_SUFFIXES for p in Path(folder).glob(pattern + suffix)}
    return sorted(p for p in found if not (p.name.endswith(".csv") and p.with_name(p.name + ".xz") in found))


def _open_text(path: Path, mode: str, **kwargs: Any) -> Any:
    """``open`` in text mode, through xz for a ``.xz`` path (written with :data:`XZ_PRESET`)."""
    if _compressed(path):
        if "w" in mode:
            return lzma.open(path, mode + "t", preset=XZ_PRESET, **kwargs)
        return lzma.open(path, mode + "t", **kwargs)
    return open(path, mode, **kwargs)


@dataclass(frozen=True, eq=False)
class CycleLog:
    """One recorded bucket-loading cycle.

    Attributes
    ----------
    path : BucketPath
        Tip path (t, x, z, blade angle).
    tangential, normal : numpy.ndarray
        Measured F_T and F_N [N].
    pile : Pile
        Pile surface at the start of the cycle.
    bucket : Bucket
        Bucket geometry.
    fill_volume : numpy.ndarray or None
        Logged bucket fill [m^3].
    measured_load : numpy.ndarray or None
        Logged soil weight in the bucket W_load [N].
    pile_after : Pile or None
        Surface after the cycle.
    metadata : dict
        Free-form JSON-serialisable information (source, soil, seed, ...).
    """

    path: BucketPath
    tangential: np.ndarray
    normal: np.ndarray
    pile: Pile
    bucket: Bucket = field(default_factory=Bucket)
    fill_volume: np.ndarray | None = None
    measured_load: np.ndarray | None = None
    pile_after: Pile | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.path, BucketPath):
            raise CycleLogError(f"CycleLog.path must be a BucketPath, got {type(self.path).__name__}")
        if not isinstance(self.pile, Pile):
            raise CycleLogError(f"CycleLog.pile must be a Pile, got {type(self.pile).__name__}")
        if not isinstance(self.bucket, Bucket):
            raise CycleLogError(f"CycleLog.bucket must be a Bucket, got {type(self.bucket).__name__}")
        n = len(self.path)
        for name in ("tangential", "normal", "fill_volume", "measured_load"):
            value = getattr(self, name)
            if value is None:
                if name in ("tangential", "normal"):
                    raise CycleLogError(f"CycleLog.{name} is required")
                continue
            arr = np.array(value, dtype=float)
            if arr.shape != (n,):
                raise CycleLogError(f"CycleLog.{name} must have one value per sample ({n}), got shape {arr.shape}")
            if not np.all(np.isfinite(arr)):
                bad = int(np.flatnonzero(~np.isfinite(arr))[0])
                raise CycleLogError(
                    f"CycleLog.{name} has NaN/inf values (first at sample {bad}, t={self.path.t[bad]:g} s)")
            if name in ("fill_volume", "measured_load") and np.any(arr < 0.0):
                raise CycleLogError(f"CycleLog.{name} must be >= 0")
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if not isinstance(self.metadata, dict):
            raise CycleLogError("CycleLog.metadata must be a dict")

    def __len__(self) -> int:
        return len(self.path)

    @property
    def resultant(self) -> np.ndarray:
        """Measured F_R = sqrt(F_T^2 + F_N^2) [N]."""
        return np.hypot(self.tangential, self.normal)

    def content_digest(self) -> str:
        """The cycle's identity by content: SHA-1 of the tangential force rounded to 1 mN (the same dig saved
        under another name, e.g. a loop's first cycle that a data set also ships, has the same digest)."""
        return hashlib.sha1(np.round(np.asarray(self.tangential), 3).tobytes()).hexdigest()

    def contact_state(self, slope_window: float = DEFAULT_SLOPE_WINDOW, fill: str = "log") -> ContactState:
        """Contact geometry of this cycle (with the tip's acceleration from the path).

        ``fill="log"`` (default) uses the logged fill or load when present; ``fill="model"`` the
        model's own bookkeeping (carving the pile along the path, as for a path never dug), the
        quantity a prediction of a new path has.
        """
        check_choice("fill", fill, ("log", "model"))
        ax, az = self.path.acceleration()
        vx, vz, _ = self.path.velocity()
        logged = fill == "log"
        return contact_state(self.path.x, self.path.z, self.path.blade_angle, self.pile, self.bucket,
                             slope_window=slope_window, fill_volume=self.fill_volume if logged else None,
                             measured_load=self.measured_load if logged else None,
                             acceleration=np.column_stack([ax, az]), velocity=np.column_stack([vx, vz]))

    # ----------------------------------------------------------------- io
    def save(self, csv_path: str | Path, overwrite: bool = False) -> Path:
        """Write ``csv_path`` and its JSON sidecar (both xz-compressed when ``csv_path`` ends in ``.csv.xz``);
        refuse to overwrite unless asked."""
        csv_path = Path(csv_path)
        sidecar = sidecar_path(csv_path)
        if not overwrite:
            for target in (csv_path, sidecar):
                if target.exists():
                    raise FileExistsError(f"{target} exists; pass overwrite=True to replace it")
        columns = {"t": self.path.t, "x": self.path.x, "z": self.path.z, "blade_angle": self.path.blade_angle,
                   "F_T": self.tangential, "F_N": self.normal}
        if self.fill_volume is not None:
            columns["fill_volume"] = self.fill_volume
        if self.measured_load is not None:
            columns["W_load"] = self.measured_load
        write_columns(csv_path, columns)
        meta = {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "pile": self.pile.to_dict(),
            "pile_after": None if self.pile_after is None else self.pile_after.to_dict(),
            "bucket": self.bucket.to_dict(),
            "metadata": self.metadata,
        }
        with _open_text(sidecar, "w") as fh:
            fh.write(json.dumps(to_jsonable(meta), indent=1, allow_nan=False))
        return csv_path

    @classmethod
    def load(cls, csv_path: str | Path, *, check: bool = True) -> CycleLog:
        """Read a cycle log (CSV + JSON sidecar) with clear errors for bad files.

        ``LOG.csv.xz`` (with ``LOG.json.xz``) is read through xz; ``LOG.csv`` that is absent while
        ``LOG.csv.xz`` is present reads the compressed log. ``check=False`` skips the checks of the forces' sign
        convention, the fill's unit and the plausibility warnings (for a plant's own logs, whose convention is
        known: e.g. an MPM cycle whose bucket scraped the soil bed below the pile's ground, where the bed pushes
        the bucket up and F_N is negative in most samples); the file's format is checked either way.
        """
        csv_path = Path(csv_path)
        if not csv_path.exists() and csv_path.name.endswith(".csv"):
            packed = csv_path.with_name(csv_path.name + COMPRESSED_SUFFIX)
            csv_path = packed if packed.is_file() else csv_path
        columns = _read_columns(csv_path, required=PATH_COLUMNS + FORCE_COLUMNS)
        path = _path_from_columns(csv_path, columns)
        sidecar = sidecar_path(csv_path)
        if not sidecar.exists():
            raise CycleLogError(f"{csv_path}: JSON sidecar {sidecar.name} not found (it holds the pile and bucket)")
        meta = read_json(sidecar, CycleLogError)
        if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
            raise CycleLogError(f'{sidecar}: "format" must be "{FORMAT_NAME}"')
        if meta.get("version") != FORMAT_VERSION:
            raise CycleLogError(f"{sidecar}: unsupported version {meta.get('version')!r} (expected {FORMAT_VERSION})")
        try:
            pile = Pile.from_dict(meta.get("pile"))
            pile_after = None if meta.get("pile_after") is None else Pile.from_dict(meta["pile_after"])
            bucket = Bucket.from_dict(meta.get("bucket") or {})
        except ParameterError as exc:
            raise CycleLogError(f"{sidecar}: {exc}") from None
        metadata = meta.get("metadata") or {}
        log = cls(path, columns["F_T"], columns["F_N"], pile, bucket, columns.get("fill_volume"),
                  columns.get("W_load"), pile_after, metadata)
        if check:
            _check_geometry(csv_path, log)
        return log


def load_path_csv(csv_path: str | Path, name: str | None = None) -> BucketPath:
    """Read a path CSV (columns t, x, z, blade_angle; extra columns ignored)."""
    csv_path = Path(csv_path)
    columns = _read_columns(csv_path, required=PATH_COLUMNS)
    return _path_from_columns(csv_path, columns, name)


def save_path_csv(path: BucketPath, csv_path: str | Path, overwrite: bool = False) -> Path:
    """Write a :class:`BucketPath` as CSV (t, x, z, blade_angle)."""
    csv_path = Path(csv_path)
    if csv_path.exists() and not overwrite:
        raise FileExistsError(f"{csv_path} exists; pass overwrite=True to replace it")
    write_columns(csv_path, {"t": path.t, "x": path.x, "z": path.z, "blade_angle": path.blade_angle})
    return csv_path


# ------------------------------------------------------------------ helpers
def write_columns(csv_path: Path, columns: dict[str, np.ndarray]) -> None:
    """Write named columns as CSV with a header row, full float precision (``repr``)."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[k], dtype=float) for k in names])
    with _open_text(csv_path, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(names)
        for row in data:
            writer.writerow([repr(float(v)) for v in row])


def _read_columns(csv_path: Path, required: tuple[str, ...]) -> dict[str, np.ndarray]:
    if not csv_path.exists():
        raise FileNotFoundError(2, "No such file", str(csv_path))
    if csv_path.is_dir():
        raise CycleLogError(f"{csv_path}: is a directory, expected a CSV file")
    # streamed: one row at a time into typed arrays (8 bytes a value), so a 200 MB log does not become
    # gigabytes of Python strings
    try:  # utf-8-sig: a byte-order mark (spreadsheet exports) is not part of the first column name
        with _open_text(csv_path, "r", newline="", encoding="utf-8-sig") as fh:
            reader = csv.reader(line for line in fh if line.strip() and not line.lstrip().startswith("#"))
            first = next(reader, None)
            if first is None:
                raise CycleLogError(f"{csv_path}: empty file (expected a header row with {', '.join(required)})")
            header = [h.strip() for h in first]
            missing = [c for c in required if c not in header]
            if missing:
                raise CycleLogError(f"{csv_path}: missing column(s) {missing}; found {header}")
            if len(set(header)) != len(header):
                raise CycleLogError(f"{csv_path}: duplicate column names in {header}")
            wanted = [c for c in header if c in PATH_COLUMNS + FORCE_COLUMNS + OPTIONAL_COLUMNS]
            columns = [(col, header.index(col), array("d")) for col in wanted]
            count = 0
            for i, row in enumerate(reader):
                if len(row) != len(header):
                    raise CycleLogError(f"{csv_path}: row {i + 2} has {len(row)} fields, header has {len(header)}")
                for col, j, buf in columns:
                    try:
                        buf.append(float(row[j]))
                    except ValueError:
                        raise CycleLogError(f"{csv_path}: row {i + 2}, column {col!r}: not a number: "
                                            f"{row[j]!r}") from None
                count += 1
    except UnicodeDecodeError as exc:
        raise CycleLogError(f"{csv_path}: not a UTF-8 text CSV file ({exc.reason} at byte {exc.start})") from None
    except lzma.LZMAError as exc:
        raise CycleLogError(f"{csv_path}: not an xz file ({exc})") from None
    if count < 2:
        raise CycleLogError(f"{csv_path}: needs at least 2 data rows, found {count}")
    out: dict[str, np.ndarray] = {}
    for col, _, buf in columns:
        values = np.frombuffer(buf, dtype=float).copy()
        if not np.all(np.isfinite(values)):
            i = int(np.flatnonzero(~np.isfinite(values))[0])
            raise CycleLogError(f"{csv_path}: column {col!r} has NaN/inf (first at row {i + 2})")
        out[col] = values
    return out


def _path_from_columns(csv_path: Path, columns: dict[str, np.ndarray], name: str | None = None) -> BucketPath:
    t = columns["t"]
    steps = np.diff(t)
    if np.any(steps <= 0.0):
        i = int(np.flatnonzero(steps <= 0.0)[0])
        raise CycleLogError(
            f"{csv_path}: time is not strictly increasing at row {i + 3} (t={float(t[i + 1])!r} after {float(t[i])!r})")
    angle = columns["blade_angle"]
    if np.max(np.abs(angle)) > math.pi:
        raise CycleLogError(
            f"{csv_path}: blade_angle reaches {np.max(np.abs(angle)):.3g}; angles must be in radians "
            "(values beyond pi look like degrees)"
        )
    return BucketPath(t, columns["x"], columns["z"], angle, name or log_stem(csv_path))


def _check_geometry(csv_path: Path, log: CycleLog) -> None:
    # Forces must be non-negative where the tip is out of soil? Real sensors have offsets; only reject
    # values that cannot be forces of this model: F_N strongly negative everywhere means a sign flip.
    if np.all(log.normal <= 0.0) and np.any(log.normal < 0.0):
        raise CycleLogError(f"{csv_path}: F_N is never positive; check the sign convention (F_N > 0 presses "
                            "the blade away from the soil wedge, eq 17)")
    in_soil = log.pile.surface_height(log.path.x) > log.path.z
    if np.any(in_soil):
        negative = float(np.mean(log.normal[in_soil] < 0.0))
        if negative > FLIPPED_FN_SHARE:
            raise CycleLogError(f"{csv_path}: F_N is negative in {negative:.0%} of the samples in soil (more than "
                                f"{FLIPPED_FN_SHARE:.0%}); check the sign convention (F_N > 0 presses the blade "
                                "away from the soil wedge, eq 17)")
    if log.fill_volume is not None and np.max(log.fill_volume) > 10.0 * log.bucket.capacity:
        raise CycleLogError(f"{csv_path}: fill_volume reaches {np.max(log.fill_volume):g} m^3, more than 10x the "
                            f"bucket capacity {log.bucket.capacity:g} m^3 (litres instead of m^3?)")
    from .plausibility import check_log

    check_log(log, str(csv_path))
