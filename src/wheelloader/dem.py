"""DEM ground truth: drive the Yade scenario ``dem/yade_scenario.py`` and read its output as cycle logs.

The scenario (see ``dem/README.md``) is a quasi-2D slab pile of spheres
(Hertz-Mindlin with rolling resistance) dug by a kinematically driven rigid
facet bucket. Yade runs its scripts on the system Python, so this module
runs ``yade -n -j1 -x dem/yade_scenario.py ...`` as a subprocess, streams its
progress, and converts the raw output (60 Hz CSV + ``summary.json``) into
:class:`~wheelloader.estimator.cyclelog.CycleLog` objects.

Geometry and units
------------------
The scene is a geometrically scaled model of the project's default scenario:
the default pile (:meth:`Pile.trapezoid`, 1 m high), the default bucket
(:class:`Bucket`) and the Fig. 8 paths (:func:`paper_paths`) are all scaled by
``scale`` (default 0.6) about the pile toe; the time axis is not scaled
(4.67 s, 281 samples at 60 Hz). The tip path is raised by one particle radius
(the granular bed replaces the paper's rigid ground; a blade skimming the bed's
top layer jams single particles).
Forces and masses are NOT rescaled: a log holds the forces on the simulated
slab, and its ``bucket.width`` is the slab width, so the FEE (linear in the
width ``w``, with ``W_load`` from a fill volume of the same slab) compares
like with like.

Noise
-----
DEM forces are noisy (single particles jam at the cutting edge). Compare
against :func:`smooth` (a Gaussian filter, :data:`DEFAULT_FILTER`), as the
paper compared with filtered forces, and report unfiltered figures too;
:func:`relative_noise` measures the noise level.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator.cyclelog import CycleLog
from wheelloader.estimator.errors import ParameterError, WheelloaderError
from wheelloader.estimator.machine import Bucket
from wheelloader.estimator.paths import BucketPath, bezier_path, paper_paths
from wheelloader.estimator.pile import Pile

#: Command that installs Yade on Debian/Ubuntu.
YADE_INSTALL = "sudo apt-get update && sudo apt-get install -y yade"
#: Soils the scenario knows (counterparts of the paper's Table 2; see dem/README.md).
SOILS: tuple[str, ...] = ("gravel", "sand", "dirt", "modified_sand")
#: The filter used for comparisons with DEM forces: Gaussian, sigma 0.1 s (FWHM 0.24 s).
DEFAULT_FILTER: dict[str, Any] = {"kind": "gaussian", "sigma_s": 0.1, "mode": "nearest"}
#: Repository root (editable install: src/wheelloader/dem.py -> ../../).
REPO_ROOT = Path(__file__).resolve().parents[2]
#: Default location of the shipped reference data.
REFERENCE_DIR = REPO_ROOT / "data" / "reference"
#: Default pile cache.
DEFAULT_CACHE = Path(os.environ.get("WHEELLOADER_DEM_CACHE", Path.home() / ".cache" / "wheelloader" / "dem"))


class YadeNotFoundError(WheelloaderError, RuntimeError):
    """The ``yade`` executable is not on PATH."""


class DemRunError(WheelloaderError, RuntimeError):
    """Yade exited with an error."""


# --------------------------------------------------------------------------- configuration
@dataclass(frozen=True)
class DemConfig:
    """Parameters of one DEM scenario run.

    Parameters
    ----------
    soil : str
        One of :data:`SOILS`.
    scale : float
        Geometric scale of pile, bucket and paths relative to the project
        defaults (1 m pile, 0.45 m bucket floor) [-].
    slab_width : float
        Slab (and bucket) width in y [m].
    radius, radius_spread : float
        Mean particle radius [m] and relative half-width of the uniform radius range.
    young : float
        Young's modulus of particles and bucket [Pa] (reduced from steel/rock
        values so that the time step is ~2e-4 s; see dem/README.md).
    seed : int
        Seed of the particle deposition.
    slope_deg : float
        Front slope of the pile [deg].
    top_length : float
        Flat top of the simulated pile up to its back wall [m].
    bed : float
        Soil bed depth under the pile and in front of it [m].
    bulk_density : float or None
        Override of the soil's target bulk density [kg/m^3].
    hold : float
        Hold at the end pose after each path [s] (measures the carried load).
    between : float
        Settling time between the cycles of a multi-cycle run [s].
    damping : float
        Newton (local) damping during the cycles [-].
    threads : int
        Yade OpenMP threads (``-j``); 1 is bit-reproducible.
    lift : float or None
        Path offset in z [m]; None = one particle radius.
    """

    soil: str = "gravel"
    scale: float = 0.6
    slab_width: float = 0.35
    radius: float = 0.03
    radius_spread: float = 0.15
    young: float = 5e7
    seed: int = 1
    slope_deg: float = 30.0
    top_length: float = 0.4
    bed: float = 0.2
    bulk_density: float | None = None
    hold: float = 0.4
    between: float = 0.3
    damping: float = 0.0
    threads: int = 1
    lift: float | None = None

    def __post_init__(self) -> None:
        if self.soil not in SOILS:
            raise ParameterError(f"soil must be one of {list(SOILS)}, got {self.soil!r}")
        for name in ("scale", "slab_width", "radius", "young", "slope_deg", "top_length", "bed", "hold"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ParameterError(f"DemConfig.{name} must be > 0, got {value!r}")
        if not 0.0 <= self.radius_spread < 0.5:
            raise ParameterError(f"radius_spread must be in [0, 0.5), got {self.radius_spread!r}")
        if self.slab_width < 4 * self.radius * (1 + self.radius_spread):
            raise ParameterError(f"slab_width {self.slab_width} m must be at least 4 particle radii")
        if self.bulk_density is not None and not self.bulk_density > 0:
            raise ParameterError(f"bulk_density must be > 0 kg/m^3, got {self.bulk_density!r}")
        if not (isinstance(self.threads, int) and self.threads >= 1):
            raise ParameterError(f"threads must be a positive int, got {self.threads!r}")

    @property
    def pile_height(self) -> float:
        """Pile height [m]: the default pile's 1 m times ``scale``."""
        return 1.0 * self.scale

    @property
    def path_lift(self) -> float:
        """z offset of the scaled paths [m]."""
        return self.radius if self.lift is None else self.lift

    def bucket(self) -> Bucket:
        """The simulated bucket as a :class:`Bucket`: default geometry x ``scale``, width = slab width."""
        ref = Bucket()
        area_scale = self.scale**2 * self.slab_width / ref.width
        return Bucket(width=self.slab_width, edge_thickness=ref.edge_thickness * self.scale,
                      floor_length=ref.floor_length * self.scale, capacity=ref.capacity * area_scale,
                      mass=ref.mass * area_scale)

    def yade_args(self) -> list[str]:
        """Scenario options for ``dem/yade_scenario.py``."""
        ref = Bucket()
        args = ["--soil", self.soil, "--radius", repr(self.radius), "--radius-spread", repr(self.radius_spread),
                "--young", repr(self.young), "--seed", str(self.seed), "--slab-width", repr(self.slab_width),
                "--pile-height", repr(self.pile_height), "--slope-deg", repr(self.slope_deg),
                "--top-length", repr(self.top_length), "--bed", repr(self.bed),
                "--floor-length", repr(ref.floor_length * self.scale),
                "--back-height", repr(BACK_HEIGHT * self.scale), "--top-plate", repr(TOP_PLATE * self.scale),
                "--hold", repr(self.hold), "--between", repr(self.between), "--damping", repr(self.damping)]
        if self.bulk_density is not None:
            args += ["--bulk-density", repr(self.bulk_density)]
        return args


#: Back-plate height and top-plate length of the full-scale bucket [m] (floor 0.45 m: struck capacity
#: 0.135 m^2 per metre of width, heaped about the Bucket default 0.2 m^3 per metre).
BACK_HEIGHT = 0.45
TOP_PLATE = 0.15


# --------------------------------------------------------------------------- paths
def _scaled(path: BucketPath, config: DemConfig, name: str | None = None) -> BucketPath:
    return BucketPath(path.t, path.x * config.scale, path.z * config.scale + config.path_lift, path.blade_angle,
                      name or path.name)


def scenario_paths(config: DemConfig | None = None) -> list[BucketPath]:
    """The four Fig. 8-style paths (:func:`paper_paths`), scaled about the toe (x = 0) and lifted."""
    config = config or DemConfig()
    return [_scaled(p, config) for p in paper_paths(0.0)]


def dual_cycle_paths(config: DemConfig | None = None) -> tuple[BucketPath, BucketPath]:
    """Fig. 9-style pair: path 1, then a path from the same start reaching 0.3 m (full scale) further in.

    The second cycle digs the surface the first carved (a run with both paths
    dumps the bucket between them).
    """
    config = config or DemConfig()
    first = paper_paths(0.0)[0]
    second = bezier_path((-0.10, 0.03), (1.50, 0.05), (1.75, 1.20), curl_from=0.6, name="dual cycle 2")
    return _scaled(first, config, "dual cycle 1"), _scaled(second, config)


def write_path_csv(path: BucketPath, fname: Path) -> None:
    """Write t, x, z, blade_angle (the scenario's input format)."""
    with open(fname, "w") as fh:
        fh.write("t,x,z,blade_angle\n")
        for row in zip(path.t, path.x, path.z, path.blade_angle, strict=True):
            fh.write(",".join(repr(float(v)) for v in row) + "\n")


# --------------------------------------------------------------------------- running Yade
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
    """Location of ``dem/yade_scenario.py`` (override with WHEELLOADER_DEM_SCRIPT)."""
    script = Path(os.environ.get("WHEELLOADER_DEM_SCRIPT", REPO_ROOT / "dem" / "yade_scenario.py"))
    if not script.exists():
        raise DemRunError(f"DEM scenario script not found at {script}; run from a source checkout or set "
                          "WHEELLOADER_DEM_SCRIPT")
    return script


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
    progress: Callable[[str], None] | None = print,
    timeout: float | None = None,
    names: Sequence[str] | None = None,
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
        Receives each progress line; None silences it.
    timeout : float, optional
        Wall-clock limit [s].
    names : sequence of str, optional
        Path names for the logs (default: the paths' names).

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
           *config.yade_args()]
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
                if progress is not None and line.startswith("[dem]"):
                    progress(line)
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


# --------------------------------------------------------------------------- noise and filters
def smooth(values: np.ndarray, rate: float = 60.0, sigma_s: float = DEFAULT_FILTER["sigma_s"]) -> np.ndarray:
    """Gaussian filter of a 60 Hz force record (``scipy.ndimage.gaussian_filter1d``, mode 'nearest')."""
    from scipy.ndimage import gaussian_filter1d

    if not (rate > 0 and sigma_s > 0):
        raise ParameterError(f"rate and sigma_s must be > 0, got {rate!r}, {sigma_s!r}")
    return gaussian_filter1d(np.asarray(values, dtype=float), sigma_s * rate, mode="nearest")


def moving_average(values: np.ndarray, rate: float = 60.0, window_s: float = 0.25) -> np.ndarray:
    """Centred moving average over ``window_s`` (shrinking at the ends)."""
    v = np.asarray(values, dtype=float)
    half = max(1, int(round(0.5 * window_s * rate)))
    c = np.concatenate([[0.0], np.cumsum(v)])
    idx = np.arange(v.size)
    lo = np.clip(idx - half, 0, v.size)
    hi = np.clip(idx + half + 1, 0, v.size)
    return (c[hi] - c[lo]) / (hi - lo)


def relative_noise(values: np.ndarray, rate: float = 60.0, window_s: float = 0.25) -> float:
    """RMS of the deviation from a ``window_s`` moving average, relative to the RMS of that average."""
    v = np.asarray(values, dtype=float)
    m = moving_average(v, rate, window_s)
    denom = float(np.sqrt(np.mean(m**2)))
    return float(np.sqrt(np.mean((v - m) ** 2)) / denom) if denom > 0 else 0.0


def filtered(log: CycleLog, sigma_s: float = DEFAULT_FILTER["sigma_s"]) -> CycleLog:
    """The same log with Gaussian-filtered F_T and F_N (metadata records the filter)."""
    rate = 1.0 / float(np.median(np.diff(log.path.t)))
    meta = dict(log.metadata, filter={"kind": "gaussian", "sigma_s": sigma_s, "mode": "nearest"})
    return replace(log, tangential=smooth(log.tangential, rate, sigma_s), normal=smooth(log.normal, rate, sigma_s),
                   metadata=meta)


# --------------------------------------------------------------------------- reference data set
@dataclass(frozen=True)
class ReferenceCase:
    """One entry of the shipped reference set: a Yade run of one or more cycles."""

    name: str
    config: DemConfig
    paths: tuple[str, ...]  # "path1".."path4", "dual1", "dual2"

    def path_objects(self) -> list[BucketPath]:
        out = []
        for key in self.paths:
            if key.startswith("path"):
                out.append(scenario_paths(self.config)[int(key[4:]) - 1])
            elif key in ("dual1", "dual2"):
                out.append(dual_cycle_paths(self.config)[int(key[4:]) - 1])
            else:  # pragma: no cover - definitions below are fixed
                raise ParameterError(f"unknown path key {key!r}")
        return out

    def file_stems(self) -> list[str]:
        if len(self.paths) == 1:
            return [self.name]
        return [f"{self.name}_cycle{i + 1}" for i in range(len(self.paths))]


def reference_cases() -> list[ReferenceCase]:
    """The reference set, in generation order."""
    cases = []
    for soil in ("gravel", "modified_sand", "dirt"):
        for k in range(1, 5):
            cases.append(ReferenceCase(f"{soil}_path{k}", DemConfig(soil=soil), (f"path{k}",)))
        if soil == "gravel":
            cases.append(ReferenceCase("gravel_dual", DemConfig(soil="gravel"), ("dual1", "dual2")))
    cases.append(ReferenceCase("gravel_dense_path1", DemConfig(soil="gravel", bulk_density=1874.5), ("path1",)))
    # seed replicates (other depositions of the same soil): the spread of the reference itself and a
    # seed-averaged gravel reference (benchmarks/paper_experiments.py)
    for seed in (2, 3):
        for k in range(1, 5):
            cases.append(ReferenceCase(f"gravel_path{k}_seed{seed}", DemConfig(soil="gravel", seed=seed),
                                       (f"path{k}",)))
    for k in range(1, 5):
        cases.append(ReferenceCase(f"sand_path{k}", DemConfig(soil="sand"), (f"path{k}",)))
    return cases


def regenerate_command(name: str) -> str:
    """The documented one-line command that regenerates a reference case."""
    return f"python dem/run.py reference --only {name}"


def generate_reference(
    case: ReferenceCase,
    out_dir: str | Path = REFERENCE_DIR,
    *,
    cache_dir: str | Path | None = None,
    work_dir: str | Path | None = None,
    progress: Callable[[str], None] | None = print,
) -> list[dict[str, Any]]:
    """Run one reference case, write its cycle logs into ``out_dir`` and update ``manifest.json``."""
    import tempfile

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "raw").mkdir(exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f"dem-{case.name}-") as tmp:
        work = Path(work_dir) / case.name if work_dir is not None else Path(tmp)
        run = run_scenario(case.config, case.path_objects(), work, cache_dir=cache_dir, progress=progress,
                           names=[f"{case.name} {p}" for p in case.paths])
        entries = []
        for i, (log, stem) in enumerate(zip(run.logs, case.file_stems(), strict=True)):
            log = replace(log, metadata=dict(log.metadata, name=stem, regenerate=regenerate_command(case.name),
                                             run_wall_s=run.wall_s))
            log.save(out / f"{stem}.csv", overwrite=True)
            shutil.copyfile(run.raw_dir / f"cycle{i + 1}.csv", out / "raw" / f"{stem}.csv")
            cycle = run.summary["cycles"][i]
            entries.append({
                "name": stem,
                "case": case.name,
                "csv": f"{stem}.csv",
                "raw_csv": f"raw/{stem}.csv",
                "soil": case.config.soil,
                "path": case.paths[i],
                "cycle": i + 1,
                "cycles_in_run": len(case.paths),
                "particles": cycle["particles"],
                "yade_version": run.summary.get("yade_version"),
                "seed": case.config.seed,
                "threads": case.config.threads,
                "bulk_density": cycle["bulk_density"],
                "settle_cached": bool(run.summary["settle"].get("cached")),
                "settle_wall_s": run.summary["settle"].get("settle_wall_s"),
                "cycle_wall_s": cycle["wall_s"],
                "run_wall_s": run.wall_s,
                "carried_mass_end_load": cycle["carried_mass_load"],
                "config": asdict(case.config),
                "command": regenerate_command(case.name),
            })
    update_manifest(out, entries)
    return entries


def update_manifest(out_dir: Path, entries: list[dict[str, Any]]) -> Path:
    """Insert or replace ``entries`` (by name) in ``out_dir/manifest.json``."""
    fname = Path(out_dir) / "manifest.json"
    manifest: dict[str, Any] = {"format": "wheelloader.dem-reference", "version": 1, "cycles": []}
    if fname.exists():
        manifest = json.loads(fname.read_text())
    keep = [e for e in manifest.get("cycles", []) if e["name"] not in {n["name"] for n in entries}]
    order = {c.name: k for k, c in enumerate(reference_cases())}
    manifest["cycles"] = sorted(keep + entries, key=lambda e: (order.get(e["case"], 999), e["cycle"]))
    manifest["filter"] = DEFAULT_FILTER
    manifest["notes"] = ("Forces per simulated slab (bucket.width = slab width); geometry = project defaults x "
                         "scale; see dem/README.md. Regenerate a case with its 'command'.")
    manifest["generated_with"] = {"python": sys.version.split()[0], "platform": sys.platform}
    tmp = fname.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(manifest, indent=1))
    tmp.replace(fname)
    return fname


def load_reference(name: str, data_dir: str | Path = REFERENCE_DIR) -> CycleLog:
    """Load a shipped reference cycle by name (e.g. ``"gravel_path1"``, ``"gravel_dual_cycle2"``)."""
    fname = Path(data_dir) / f"{name}.csv"
    if not fname.exists():
        raise ParameterError(f"no reference cycle {name!r} in {data_dir} (see manifest.json)")
    return CycleLog.load(fname)


# --------------------------------------------------------------------------- sanity figures
def sanity_figures(log: CycleLog, raw: dict[str, np.ndarray] | None = None) -> dict[str, float]:
    """Physical sanity figures of one DEM cycle.

    * ``force_before_contact``: largest |F| while no particle touches the bucket [N] (must be 0);
    * ``depth_force_spearman``: rank correlation of depth (to the start surface) and filtered F_R over
      the in-soil samples before the curl (force grows with depth: > 0);
    * ``carried_mass``: load carried at the end of the hold [kg]; ``carve_mass``: the project's geometric
      carve of the start surface along the path (``Pile.carve``, capped by capacity) x bulk density [kg];
    * ``mass_ratio``: ``carried_mass / carve_mass`` (stated tolerance: :data:`MASS_TOLERANCE`);
    * ``mean_depth``: mean depth to the start surface over the in-soil samples [m];
    * ``relative_noise``: noise of F_R around a 0.25 s moving average.

    With the raw record (``raw``) also:

    * ``force_before_contact``: largest |F| in a sample window with no real contact on the bucket at that
      sample and its two neighbours [N]; the force is a sum of contact forces, so it is 0 unless a
      particle touched the bucket between two sample instants;
    * ``no_contact_windows`` and ``no_contact_zero_fraction``: the number of such windows and the
      fraction of them whose force is exactly 0.
    """
    from scipy.stats import spearmanr

    state = log.contact_state()
    fr = smooth(log.resultant)
    in_soil = state.depth > 0.0
    n_half = int(0.55 * len(log))
    sel = in_soil.copy()
    sel[n_half:] = False
    rho = float(spearmanr(state.depth[sel], fr[sel]).statistic) if sel.sum() > 5 else float("nan")
    carve = log.pile.carve(log.path.x, log.path.z, log.bucket.width, log.bucket.capacity)
    bulk = float(log.metadata.get("bulk_density", float("nan")))
    out = {
        "depth_force_spearman": rho,
        "carried_mass": float(log.metadata.get("carried_mass_end_load", float("nan"))),
        "carve_mass": carve.in_bucket * bulk,
        "carve_removed_mass": carve.removed * bulk,
        "mass_ratio": float(log.metadata.get("carried_mass_end_load", float("nan"))) / (carve.in_bucket * bulk)
        if carve.in_bucket > 0 else float("nan"),
        "mean_depth": float(np.mean(state.depth[in_soil])) if in_soil.any() else 0.0,
        "relative_noise": relative_noise(log.resultant),
        "mean_resultant": float(np.mean(log.resultant)),
        "peak_resultant_filtered": float(np.max(fr)),
    }
    if raw is not None:
        f = np.hypot(raw["Fx"], raw["Fz"])
        free = (raw["contacts"] == 0) & (np.roll(raw["contacts"], 1) == 0) & (np.roll(raw["contacts"], -1) == 0)
        free[0] = raw["contacts"][0] == 0
        out["force_before_contact"] = float(np.max(f[free])) if free.any() else float("nan")
        out["no_contact_windows"] = int(free.sum())
        out["no_contact_zero_fraction"] = float(np.mean(f[free] == 0.0)) if free.any() else float("nan")
    return out


#: Stated tolerance of the mass check: the load carried at the end of a cycle / (the project's geometric
#: carve of the start surface x bulk density) lies within 1 -+ MASS_TOLERANCE. The carve is the FEE's
#: idealisation (a rigid-bucket swept area), not an exact mass balance: soil heaps above the strike line
#: and spills over the edges, so +-30 % is what is asserted (measured range on data/reference: 0.73-1.24).
MASS_TOLERANCE = 0.30


def sanity_report(data_dir: str | Path = REFERENCE_DIR) -> dict[str, Any]:
    """Sanity figures over a reference directory.

    Per cycle (:func:`sanity_figures`), then the checks across cycles:

    * ``depth``: per soil with paths 1-4, the paths ordered by mean depth and their mean F_R; ``monotone``
      is true when the force grows with the depth (the within-cycle rank correlation is weak: particle-scale
      events dominate single samples);
    * ``mass``: the range of ``mass_ratio`` and whether every cycle lies within :data:`MASS_TOLERANCE`;
    * ``zero force out of contact``: the cycles with a non-zero force in a contact-free window;
    * the density (``gravel_dense_path1`` / ``gravel_path1``) and seed (``gravel_path1_seed2`` /
      ``gravel_path1``) ratios.
    """
    data_dir = Path(data_dir)
    manifest = json.loads((data_dir / "manifest.json").read_text())
    per_cycle: dict[str, dict[str, float]] = {}
    for entry in manifest["cycles"]:
        log = CycleLog.load(data_dir / entry["csv"])
        raw_file = data_dir / entry["raw_csv"]
        raw = None
        if raw_file.exists():
            data = np.genfromtxt(raw_file, delimiter=",", names=True)
            raw = {n: np.asarray(data[n], dtype=float) for n in data.dtype.names}
        per_cycle[entry["name"]] = sanity_figures(log, raw)
    report: dict[str, Any] = {"filter": DEFAULT_FILTER, "cycles": per_cycle}
    depth: dict[str, Any] = {}
    for soil in SOILS:
        names = [f"{soil}_path{k}" for k in range(1, 5)]
        if not all(n in per_cycle for n in names):
            continue
        ordered = sorted(names, key=lambda n: per_cycle[n]["mean_depth"])
        forces = [per_cycle[n]["mean_resultant"] for n in ordered]
        depth[soil] = {"paths_by_depth": ordered, "mean_depth": [per_cycle[n]["mean_depth"] for n in ordered],
                       "mean_resultant": forces, "monotone": bool(np.all(np.diff(forces) > 0))}
    report["depth"] = depth
    ratios = {n: c["mass_ratio"] for n, c in per_cycle.items()}
    if ratios:
        report["mass"] = {"tolerance": MASS_TOLERANCE, "min_ratio": min(ratios.values()),
                          "max_ratio": max(ratios.values()),
                          "within_tolerance": all(abs(r - 1.0) <= MASS_TOLERANCE for r in ratios.values())}
    report["zero force out of contact"] = {
        n: {"max_force": c["force_before_contact"], "zero_fraction": c["no_contact_zero_fraction"]}
        for n, c in per_cycle.items() if c.get("force_before_contact", 0.0) > 0.0}
    pairs = {"density (gravel_dense_path1 / gravel_path1)": ("gravel_dense_path1", "gravel_path1"),
             "seed (gravel_path1_seed2 / gravel_path1)": ("gravel_path1_seed2", "gravel_path1")}
    for label, (a, b) in pairs.items():
        if a in per_cycle and b in per_cycle:
            report[label] = {
                "mean_resultant_ratio": per_cycle[a]["mean_resultant"] / per_cycle[b]["mean_resultant"],
                "carried_mass_ratio": per_cycle[a]["carried_mass"] / per_cycle[b]["carried_mass"],
            }
    return report


# --------------------------------------------------------------------------- command line
def _config_from_args(args: Any, soil: str) -> DemConfig:
    return DemConfig(soil=soil, scale=args.scale, slab_width=args.slab_width, radius=args.radius, young=args.young,
                     seed=args.seed, bulk_density=args.bulk_density, threads=args.threads)


def _cmd_reference(args: Any) -> int:
    cases = reference_cases()
    if args.only:
        known = {c.name: c for c in cases}
        unknown = [n for n in args.only if n not in known]
        if unknown:
            raise ParameterError(f"unknown reference case(s) {unknown}; choose from {sorted(known)}")
        cases = [known[n] for n in args.only]
    out = Path(args.out)
    for k, case in enumerate(cases):
        if args.skip_existing and all((out / f"{s}.csv").exists() for s in case.file_stems()):
            print(f"[{k + 1}/{len(cases)}] {case.name}: exists, skipped", flush=True)
            continue
        print(f"[{k + 1}/{len(cases)}] {case.name}: soil={case.config.soil} paths={','.join(case.paths)}", flush=True)
        t0 = time.time()
        generate_reference(case, out, cache_dir=args.cache_dir, progress=lambda s: print("   " + s, flush=True))
        print(f"[{k + 1}/{len(cases)}] {case.name}: done in {time.time() - t0:.1f} s", flush=True)
    return 0


def _cmd_list(args: Any) -> int:
    for case in reference_cases():
        print(f"{case.name:24s} soil={case.config.soil:14s} paths={','.join(case.paths):12s} "
              f"seed={case.config.seed}  ->  {regenerate_command(case.name)}")
    return 0


def _cmd_cycle(args: Any) -> int:
    config = _config_from_args(args, args.soil)
    if args.path == "dual":
        paths = list(dual_cycle_paths(config))
    else:
        paths = [scenario_paths(config)[int(args.path) - 1]]
    out = Path(args.out)
    run = run_scenario(config, paths, out, cache_dir=args.cache_dir)
    for i, log in enumerate(run.logs):
        fname = out / f"cycle{i + 1}.csv"
        log.save(fname, overwrite=True)
        print(f"wrote {fname} ({len(log)} samples, {log.metadata['particles']} particles, "
              f"mean F_R {np.mean(log.resultant):.1f} N, carried {log.metadata['carried_mass_end_load']:.2f} kg)")
    print(f"Yade run: {run.wall_s:.1f} s")
    return 0


def _cmd_sanity(args: Any) -> int:
    report = sanity_report(args.data)
    text = json.dumps(report, indent=1)
    if args.json:
        Path(args.json).write_text(text)
    print(text)
    return 0


def register(subparsers: Any) -> None:
    """Add the ``dem`` command (subcommands reference, list, cycle, sanity) to a CLI."""
    p = subparsers.add_parser("dem", help="DEM (Yade) ground-truth scenario and reference data")
    _add_dem_subcommands(p)


def _add_dem_subcommands(parser: Any) -> None:
    sub = parser.add_subparsers(title="dem commands", metavar="SUBCOMMAND")
    p = sub.add_parser("reference", help="(re)generate the shipped reference cycles")
    p.add_argument("--only", nargs="+", metavar="NAME", help="case names (see 'list'); default: all")
    p.add_argument("--out", default=str(REFERENCE_DIR), help="output directory (default data/reference)")
    p.add_argument("--cache-dir", default=None, help="settled-pile cache (default ~/.cache/wheelloader/dem)")
    p.add_argument("--skip-existing", action="store_true", help="skip cases whose files exist")
    p.set_defaults(func=_cmd_reference)
    p = sub.add_parser("list", help="list the reference cases and their regeneration commands")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("cycle", help="run one scenario and write its cycle log(s)")
    p.add_argument("--soil", default="gravel", choices=SOILS)
    p.add_argument("--path", default="1", choices=["1", "2", "3", "4", "dual"])
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--scale", type=float, default=0.6)
    p.add_argument("--slab-width", type=float, default=0.35)
    p.add_argument("--radius", type=float, default=0.03)
    p.add_argument("--young", type=float, default=5e7)
    p.add_argument("--bulk-density", type=float, default=None)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--cache-dir", default=None)
    p.set_defaults(func=_cmd_cycle)
    p = sub.add_parser("sanity", help="physical sanity figures of a reference directory")
    p.add_argument("--data", default=str(REFERENCE_DIR))
    p.add_argument("--json", default=None, help="also write the report here")
    p.set_defaults(func=_cmd_sanity)


def main(argv: Sequence[str] | None = None) -> int:
    """``python dem/run.py SUBCOMMAND ...``"""
    import argparse

    parser = argparse.ArgumentParser(prog="dem/run.py", description="DEM (Yade) ground truth for wheelloader")
    _add_dem_subcommands(parser)
    args = parser.parse_args(argv)
    if not hasattr(args, "func"):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except WheelloaderError as exc:
        print(f"dem/run.py: error: {exc}", file=sys.stderr)
        return 2


# --------------------------------------------------------------------------- tiny scenario (CI smoke test)
def tiny_config(**changes: Any) -> DemConfig:
    """A ~400-sphere scenario that settles and runs in well under a minute (CI smoke test)."""
    base = {"scale": 0.4, "slab_width": 0.28, "radius": 0.035, "top_length": 0.2, "bed": 0.15, "hold": 0.4}
    base.update(changes)
    return DemConfig(**base)


def tiny_path(config: DemConfig | None = None, duration: float = 2.0) -> BucketPath:
    """A short digging path for :func:`tiny_config`; it starts in the air in front of the pile."""
    config = config or tiny_config()
    s = config.scale
    return bezier_path((-0.15 * s, 0.15 * s), (1.0 * s, 0.10 * s), (1.3 * s, 1.1 * s), duration=duration,
                       curl_from=0.5, name="tiny")
