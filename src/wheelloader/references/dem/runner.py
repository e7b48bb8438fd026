"""Running the Yade scenario (``yade_scenario.py`` beside this module) and reading its output as cycle logs.

Yade runs its scripts on the system Python, so :func:`run_scenario` runs ``yade -n -j1 -x
yade_scenario.py ...`` as a subprocess, streams its progress, and converts the raw output (60 Hz CSV +
``summary.json``) into :class:`~wheelloader.estimator.CycleLog` objects.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import subprocess
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, CycleLog, ParameterError, Pile

from ..filtering import DEFAULT_FILTER
from .config import YADE_INSTALL, DemConfig, DemRunError, YadeNotFoundError, write_path_csv

#: Default pile cache.
DEFAULT_CACHE = Path(os.environ.get("WHEELLOADER_DEM_CACHE", Path.home() / ".cache" / "wheelloader" / "dem"))


def find_yade(executable: str | None = None) -> str:
    """Path of the Yade executable, or :class:`YadeNotFoundError` with the install command."""
    name = executable or os.environ.get("WHEELLOADER_YADE", "yade")
    found = shutil.which(name)
    if found is None:
        raise YadeNotFoundError(
            f"the Yade DEM engine ({name!r}) is not on PATH. Install it with:  {YADE_INSTALL}  "
            "(Debian 12 / Ubuntu package 'yade', tested with 2023.02a), or set WHEELLOADER_YADE."
        )
    return found


def scenario_script() -> Path:
    """Location of the Yade scenario script (installed beside this module; override with
    WHEELLOADER_DEM_SCRIPT)."""
    script = Path(os.environ.get("WHEELLOADER_DEM_SCRIPT", Path(__file__).with_name("yade_scenario.py")))
    if not script.exists():
        raise DemRunError(f"DEM scenario script not found at {script}; reinstall wheelloader or set "
                          "WHEELLOADER_DEM_SCRIPT")
    return script

_log = logging.getLogger(__name__)


@dataclass
class DemRun:
    """Result of one Yade run: its cycle logs, the raw summary, and timings."""

    logs: list[CycleLog]
    summary: dict[str, Any]
    raw_dir: Path
    wall_s: float
    command: list[str] = field(default_factory=list)


def run_scenario(
    config: DemConfig,
    paths: Sequence[BucketPath],
    work_dir: str | Path,
    *,
    cache_dir: str | Path | None = None,
    yade: str | None = None,
    progress: Callable[[str], None] | None = None,
    timeout: float | None = None,
    names: Sequence[str] | None = None,
    extra_args: Sequence[str] = (),
) -> DemRun:
    """Run the scenario for ``paths`` (one Yade run, cycles in sequence on the same pile).

    Parameters
    ----------
    config : DemConfig
        Scenario parameters.
    paths : sequence of BucketPath
        One path per cycle (tip position and blade angle, scenario coordinates).
    work_dir : path
        Directory for the path CSVs and Yade's raw output (created).
    cache_dir : path, optional
        Settled-pile cache (default ``~/.cache/wheelloader/dem`` or $WHEELLOADER_DEM_CACHE).
    yade : str, optional
        Yade executable (default ``yade`` on PATH).
    progress : callable, optional
        Receives each progress line (default: this module's logger at INFO level).
    timeout : float, optional
        Wall-clock limit [s].
    names : sequence of str, optional
        Path names for the logs (default: the paths' names).
    extra_args : sequence of str
        More scenario options (e.g. ``--surface FILE --x-back X``: a deposit carved to a given surface).

    Returns
    -------
    DemRun
    """
    if not paths:
        raise ParameterError("paths must hold at least one BucketPath")
    exe = find_yade(yade)
    script = scenario_script()
    work = Path(work_dir)
    raw = work / "raw"
    raw.mkdir(parents=True, exist_ok=True)
    cache = Path(cache_dir) if cache_dir is not None else DEFAULT_CACHE
    cmd = [exe, "-n", f"-j{config.threads}", "-x", str(script), "--out", str(raw), "--cache-dir", str(cache),
           *config.yade_args(), *extra_args]
    for i, path in enumerate(paths):
        fname = work / f"path{i + 1}.csv"
        write_path_csv(path, fname)
        cmd += ["--path", str(fname)]
    env = dict(os.environ, OMP_NUM_THREADS=str(config.threads), PYTHONUNBUFFERED="1")
    t0 = time.time()
    tail: deque[str] = deque(maxlen=40)
    with subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                          stdin=subprocess.DEVNULL) as proc:
        assert proc.stdout is not None
        try:
            for line in proc.stdout:
                line = line.rstrip()
                tail.append(line)
                if line.startswith("[dem]"):
                    (progress or _log.info)(line)
                if timeout is not None and time.time() - t0 > timeout:
                    proc.kill()
                    raise DemRunError(f"Yade run exceeded {timeout:g} s")
            rc = proc.wait()
        except BaseException:
            proc.kill()
            raise
    wall = time.time() - t0
    summary_file = raw / "summary.json"
    if rc != 0 or not summary_file.exists():
        raise DemRunError(f"Yade exited with status {rc} (no {summary_file.name}); last output:\n" + "\n".join(tail))
    summary = json.loads(summary_file.read_text())
    names = list(names) if names is not None else [p.name for p in paths]
    logs = read_raw(raw, config, names, summary)
    return DemRun(logs, summary, raw, wall, cmd)


# --------------------------------------------------------------------------- conversion
def read_raw_cycle(raw_dir: str | Path, index: int) -> dict[str, np.ndarray]:
    """Columns of ``cycle<index+1>.csv`` (path and hold samples) as arrays."""
    fname = Path(raw_dir) / f"cycle{index + 1}.csv"
    data = np.genfromtxt(fname, delimiter=",", names=True)
    return {name: np.asarray(data[name], dtype=float) for name in data.dtype.names}


def read_raw(raw_dir: str | Path, config: DemConfig, names: Sequence[str] | None = None,
             summary: dict[str, Any] | None = None) -> list[CycleLog]:
    """Convert the scenario's raw output into one :class:`CycleLog` per cycle.

    The log holds the path samples only (the hold is in the raw CSV). Its
    ``fill_volume`` is the mass of particles whose centre lies inside the
    bucket outline divided by the pile's measured bulk density (a lower bound:
    soil heaped above the strike line is not counted); the load carried at
    the end is in the metadata.
    """
    raw_dir = Path(raw_dir)
    if summary is None:
        summary = json.loads((raw_dir / "summary.json").read_text())
    bucket = config.bucket()
    logs = []
    for i, cycle in enumerate(summary["cycles"]):
        cols = read_raw_cycle(raw_dir, i)
        on_path = cols["phase"] == 0
        name = names[i] if names is not None and i < len(names) else f"cycle {i + 1}"
        path = BucketPath(cols["t"][on_path], cols["x"][on_path], cols["z"][on_path],
                          cols["blade_angle"][on_path], name)
        pile = Pile.from_polyline(cycle["pile_before"]["x"], cycle["pile_before"]["z"], spacing=0.01)
        after = Pile.from_polyline(cycle["pile_after"]["x"], cycle["pile_after"]["z"], spacing=0.01)
        bulk = float(cycle["bulk_density"])
        fill = cols["mass_inside"][on_path] / bulk
        metadata = {
            "source": "yade",
            "generator": "dem/yade_scenario.py",
            "yade_version": summary.get("yade_version"),
            "scenario_version": summary.get("scenario_version"),
            "soil": config.soil,
            "material": summary.get("material"),
            "path": name,
            "cycle": i + 1,
            "cycles_in_run": len(summary["cycles"]),
            "config": asdict(config),
            "scale": config.scale,
            "particles": cycle["particles"],
            "particle_radius": config.radius,
            "bulk_density": bulk,
            "dt": summary.get("dt"),
            "carried_mass_end_load": cycle["carried_mass_load"],
            "carried_mass_end_geometric": cycle["carried_mass_geometric"],
            "mass_inside_end": cycle["mass_inside_end"],
            "max_tracking_error": cycle["max_tracking_error"],
            "cycle_wall_s": cycle["wall_s"],
            "forces": "total soil force on the bucket facets, averaged over each 1/60 s sample window (unfiltered); "
                      "F_T along the blade tip->back, F_N normal, pressing the floor away from the soil above",
            "fill_volume": "particles with centre inside the bucket outline / bulk_density (lower bound)",
            "width": "forces and volumes are per simulated slab; bucket.width is the slab width",
            "recommended_filter": DEFAULT_FILTER,
        }
        logs.append(CycleLog(path, cols["F_T"][on_path], cols["F_N"][on_path], pile, bucket,
                             fill_volume=fill, pile_after=after, metadata=metadata))
    return logs
