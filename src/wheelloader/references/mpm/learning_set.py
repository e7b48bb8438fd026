"""New MPM cycles for the learned force correction (issue #32): a seeded design, resumable, one cycle per case.

::

    nice -n 15 python -m wheelloader.references.mpm.learning_set --out data/learn --count 64
    python -m wheelloader.references.mpm.learning_set --list --count 8

The design spans what the shipped set (``data/mpm``, ``data/results/*/cycles``) does not: soils drawn
around and between the presets (friction angle 28-46 deg, density 1350-1950 kg/m^3, wall friction
0.45-0.85 of phi; 40 % of them cohesive, c 0.5-6 kPa, adhesion 0.5-1.2 c), pile angles 20, 30 and 35 deg
(25 deg stays out: the shipped set's held-out pile), Bezier paths whose control point reaches 0.8-1.5 m into
the pile and 0.12 m below to 0.10 m above the toe (depths up to about one floor length), curl onset 0.40-0.75
of the path, durations 3.5-7 s (speed) and the cutting edge: sharp (the plant's line plates) or blunt, a front
face 1.5-4.5 cm high at the tip (a fourth plate; the cross-check against another MPM implementation showed the
edge decides the entry force, ``../shared/mpm-notes.md``). The presets ``dirt`` and ``modified_sand`` are never
drawn (they are the shipped set's held-out soils). Points come from a scrambled Sobol sequence
(:class:`scipy.stats.qmc.Sobol`, ``seed``), so any prefix of the design is already spread; they come in groups of
three paths (shallow, middle, deep control point) on one soil, pile and edge: a case family, split as a whole.

Each case is a unit of :mod:`wheelloader.sweep` (``--ray off|local|auto|ADDRESS``; serial without Ray) and is
written as soon as it finishes (``NAME.csv.xz`` + ``NAME.json.xz``) with its entry
in ``manifest.json`` (the drawn inputs, cost, load, the commit it was dug at); a case whose files exist is skipped,
so an interrupted run resumes. Progress lines go to ``OUT/progress.log``. Sets dug apart (other machines, other
folders) join with ``--merge DIR ...``: their files are copied in (never over a file that differs) and their
entries merged, each source's provenance kept under ``batches``.

The split (:func:`group_part`), fixed by the group's number before any cycle is dug, so a larger design adds
groups to both parts the same way: every :data:`VALIDATION_EVERY`-th group from group
:data:`VALIDATION_OFFSET` on (01, 05, 09, ...) is validation, the rest train. The manifest states it (``split``).
The test cycles are not here: ``data/mpm``'s smooth paths, whose soils ``dirt`` and ``modified_sand`` and
25 deg pile the design never draws.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, CycleLog, Pile, SoilParams, bezier_path
from wheelloader.provenance import machine_info
from wheelloader.ray_mode import add_ray_arguments
from wheelloader.sweep import Unit, run_sweep

from .plant import DEFAULT_RESOLUTION, MPMPlant
from .tool import Plate, ToolShape, bucket_shape

FORMAT_NAME = "wheelloader.mpm-learning-set"
#: Pile angles of the design [deg] (25 deg is held out).
SLOPES_DEG = (20.0, 30.0, 35.0)
#: Share of cohesive soils in the design.
COHESIVE_SHARE = 0.4
#: Share of blunt edges in the design.
BLUNT_SHARE = 0.5
#: Paths per group (one soil, pile and edge).
PATHS_PER_GROUP = 3
#: Every VALIDATION_EVERY-th group, from number VALIDATION_OFFSET on, is validation (:func:`group_part`).
VALIDATION_EVERY = 4
VALIDATION_OFFSET = 1
SPLIT_RULE = (f"by case family (a group: one soil, pile and edge with its {PATHS_PER_GROUP} paths; whole), fixed by "
              f"the group's number before digging: group number % {VALIDATION_EVERY} == {VALIDATION_OFFSET} is "
              "validation, the rest train; test: data/mpm's smooth paths (never here; their soils dirt and "
              "modified_sand and their 25 deg pile are never drawn)")


@dataclass(frozen=True)
class LearnCase:
    """One drawn case: a soil, a pile angle, a Bezier path and the cutting edge."""

    name: str
    soil: dict[str, float]
    soil_family: str
    slope_deg: float
    start: tuple[float, float]
    control: tuple[float, float]
    end: tuple[float, float]
    curl_from: float
    duration: float
    angle_end_deg: float
    edge_height: float

    def path(self, rate: float = 60.0) -> BucketPath:
        return bezier_path(self.start, self.control, self.end, duration=self.duration, rate=rate,
                           curl_from=self.curl_from, angle_end=math.radians(self.angle_end_deg), name=self.name)

    def pile(self) -> Pile:
        return Pile.trapezoid(angle=math.radians(self.slope_deg))

    def soil_params(self) -> SoilParams:
        return SoilParams(**self.soil)


def _lerp(u: float, lo: float, hi: float) -> float:
    return float(lo + (hi - lo) * u)


def design(count: int, seed: int = 0) -> list[LearnCase]:
    """The first ``count`` cases of the seeded design (module docstring): groups of :data:`PATHS_PER_GROUP`
    paths on one soil, pile and edge (a case family), so that a group is a small transfer set of its own."""
    from scipy.stats import qmc

    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    groups = math.ceil(count / PATHS_PER_GROUP)
    g_points = qmc.Sobol(8, scramble=True, seed=seed).random(2 ** math.ceil(math.log2(groups)))[:groups]
    p_points = qmc.Sobol(6, scramble=True, seed=seed + 1).random(
        2 ** math.ceil(math.log2(groups * PATHS_PER_GROUP)))[:groups * PATHS_PER_GROUP]
    out = []
    for k in range(count):
        g, u, v = k // PATHS_PER_GROUP, g_points[k // PATHS_PER_GROUP], p_points[k]
        cohesive = u[0] < COHESIVE_SHARE
        phi = math.radians(_lerp(u[1], 28.0, 46.0))
        cohesion = _lerp(u[3], 500.0, 6000.0) if cohesive else 0.0
        soil = {"gamma": round(_lerp(u[2], 1350.0, 1950.0), 1), "cohesion": round(cohesion, 1),
                "adhesion": round(cohesion * _lerp(u[7], 0.5, 1.2), 1), "phi": round(phi, 4),
                "delta": round(phi * _lerp(u[4], 0.45, 0.85), 4),
                # Bekker terms: unused by the plant; the gravel preset's, so the log's soil is a valid SoilParams
                "k_c": 1274.0, "k_phi": 177.4, "n": 1.21}
        slope = SLOPES_DEG[min(int(u[5] * len(SLOPES_DEG)), len(SLOPES_DEG) - 1)]
        blunt = u[6] < BLUNT_SHARE
        # the group's paths: the k-th of the group reaches shallow, middle or deep (control point), the rest drawn
        depth = ((k % PATHS_PER_GROUP) + v[0]) / PATHS_PER_GROUP
        cx, cz = _lerp(depth, 0.8, 1.5), _lerp(v[1], -0.12, 0.10)
        out.append(LearnCase(
            name=f"learn{g:02d}{'abc'[k % PATHS_PER_GROUP]}", soil=soil,
            soil_family="cohesive" if cohesive else "cohesionless", slope_deg=slope,
            start=(-0.10, round(_lerp(v[5], 0.0, 0.06), 3)), control=(round(cx, 3), round(cz, 3)),
            end=(round(cx + _lerp(v[2], 0.15, 0.45), 3), 1.20), curl_from=round(_lerp(v[3], 0.40, 0.75), 3),
            duration=round(_lerp(v[4], 3.5, 7.0), 2), angle_end_deg=45.0,
            edge_height=round(_lerp(u[6] / BLUNT_SHARE, 0.015, 0.045), 3) if blunt else 0.0))
    return out


def edge_shape(bucket: Bucket, edge_height: float) -> ToolShape:
    """The plant's bucket (:func:`.tool.bucket_shape`), with a blunt front face ``edge_height`` [m] below the
    floor at the tip when ``edge_height > 0`` (a fourth plate; the fill outline is unchanged)."""
    shape = bucket_shape(bucket)
    if edge_height <= 0.0:
        return shape
    return ToolShape(shape.plates + (Plate((0.0, -edge_height), (0.0, 0.0)),), shape.outline)


@functools.lru_cache(maxsize=4)
def _process_plant(resolution: float, threads: int, edge_height: float) -> MPMPlant:
    plant = MPMPlant(resolution, threads=threads)
    plant.shape = edge_shape(plant.bucket, edge_height)
    return plant


def dig_unit(case: LearnCase, resolution: float, threads: int, rate: float) -> CycleLog:
    """Dig one case (a sweep unit; builds its plant in the process it runs in)."""
    plant = _process_plant(resolution, threads, case.edge_height)
    load = machine_info()["loadavg_1_5_15min"]
    cpu0 = time.process_time()
    log = plant.dig(case.path(rate), case.pile(), case.soil_params(), seed=int(case.name[5:7]))
    meta = dict(log.metadata, name=case.name, case=asdict(case), loadavg_start=load,
                loadavg_end=machine_info()["loadavg_1_5_15min"], cpu_s=time.process_time() - cpu0,
                regenerate=f"python -m wheelloader.references.mpm.learning_set --only {case.name}")
    return CycleLog(log.path, log.tangential, log.normal, log.pile, log.bucket, log.fill_volume, log.measured_load,
                    log.pile_after, meta)


def max_depth(log: CycleLog) -> float:
    """Deepest tip depth below the start pile's surface [m]."""
    return float(np.max(np.asarray(log.pile.surface_height(log.path.x)) - log.path.z))


def group_part(name: str) -> str:
    """``"validation"`` or ``"train"`` for a case or group name (``learnGG`` or ``learnGGx``): the split rule
    (module docstring, :data:`SPLIT_RULE`)."""
    number = int(name[5:7])
    return "validation" if number % VALIDATION_EVERY == VALIDATION_OFFSET else "train"


def manifest_split(names: Sequence[str]) -> dict[str, Any]:
    """The manifest's ``split``: the rule and the groups of ``names`` (case names) per part."""
    groups = sorted({n[:7] for n in names})
    return {"rule": SPLIT_RULE, **{part: [g for g in groups if group_part(g) == part]
                                   for part in ("train", "validation")}}


def _manifest(out: Path) -> dict[str, Any]:
    fname = out / "manifest.json"
    if fname.exists():
        return json.loads(fname.read_text())
    return {"format": FORMAT_NAME, "version": 1, "cycles": []}


def write_cycle(case: LearnCase, log: CycleLog, out: Path) -> dict[str, Any]:
    """Save ``log`` as ``NAME.csv.xz`` and enter it in the manifest."""
    log.save(out / f"{case.name}.csv.xz", overwrite=True)
    m = log.metadata
    machine = machine_info()
    entry = {"name": case.name, "csv": f"{case.name}.csv.xz", "case": asdict(case),
             "max_depth_over_length": round(max_depth(log) / log.bucket.floor_length, 4),
             "max_resultant_N": round(float(np.max(log.resultant)), 1),
             "final_fill_m3": round(float(log.fill_volume[-1]), 5),
             "seed": m.get("seed"), "resolution": m.get("resolution"), "particles": m.get("particles"),
             "steps": m.get("steps"), "wall_s": m.get("wall_s"), "cpu_s": m.get("cpu_s"),
             "taichi_threads": m.get("taichi_threads"), "loadavg_start": m.get("loadavg_start"),
             "loadavg_end": m.get("loadavg_end"), "command": m.get("regenerate"), "git": machine["git"]}
    manifest = _manifest(out)
    manifest["cycles"] = sorted([e for e in manifest["cycles"] if e["name"] != case.name] + [entry],
                                key=lambda e: e["name"])
    manifest["generated_with"] = {k: v for k, v in machine.items() if k != "loadavg_1_5_15min"}
    _write_manifest(out, manifest)
    return entry


def _write_manifest(out: Path, manifest: dict[str, Any]) -> None:
    manifest.setdefault("notes", "Plane-strain MPM cycles for the learned correction "
                        "(wheelloader.references.mpm.learning_set; design in the module docstring). Forces [N] for "
                        "the default 1 m wide bucket.")
    manifest["split"] = manifest_split([e["name"] for e in manifest["cycles"]])
    tmp = out / "manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=1) + "\n")
    tmp.replace(out / "manifest.json")


def merge(out: Path, sources: Sequence[Path]) -> list[str]:
    """Copy the cycles ``sources`` (learning-set folders) list into ``out`` and merge their manifest entries
    (sorted by name); each source's ``generated_with`` is kept under ``batches``. A file already in ``out`` is
    never overwritten: the same bytes are skipped, other bytes are refused (ValueError), as is an entry whose
    name ``out`` lists with another case. Returns the names added."""
    import shutil

    out.mkdir(parents=True, exist_ok=True)
    manifest = _manifest(out)
    entries = {e["name"]: e for e in manifest["cycles"]}
    plan: list[tuple[Path, Path]] = []
    added: list[str] = []
    batches = manifest.setdefault("batches", [])
    for src in sources:
        theirs = _manifest(src)
        if not theirs["cycles"]:
            raise ValueError(f"{src} has no manifest.json with cycles")
        for e in theirs["cycles"]:
            if e["name"] in entries and entries[e["name"]]["case"] != e["case"]:
                raise ValueError(f"{e['name']}: {src} and {out} list different cases")
            for fname in (f"{e['name']}.csv.xz", f"{e['name']}.json.xz"):
                a, b = src / fname, out / fname
                if not a.is_file():
                    raise ValueError(f"{a} is listed in its manifest but missing")
                if b.exists() and b.read_bytes() != a.read_bytes():
                    raise ValueError(f"{b} exists with other contents; not overwritten")
                if not b.exists():
                    plan.append((a, b))
        names = sorted(e["name"] for e in theirs["cycles"] if e["name"] not in entries)
        entries.update({e["name"]: e for e in theirs["cycles"] if e["name"] in names})
        added += names
        if names:
            batches.append({"cycles": f"{names[0]}-{names[-1]}", "count": len(names), "merged_from": str(src),
                            "generated_with": theirs.get("generated_with")})
    for a, b in plan:
        shutil.copyfile(a, b)
    manifest["cycles"] = sorted(entries.values(), key=lambda e: e["name"])
    _write_manifest(out, manifest)
    return sorted(added)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wheelloader.references.mpm.learning_set",
                                     description="Generate MPM cycles for the learned correction (resumable).")
    parser.add_argument("--out", default="data/learn", help="output directory (default data/learn)")
    parser.add_argument("--count", type=int, default=64, help="cases of the design (default 64)")
    parser.add_argument("--seed", type=int, default=0, help="Sobol scramble seed (default 0)")
    parser.add_argument("--only", nargs="*", default=None, help="case names (default: all not yet done)")
    parser.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION, help="grid cell size [m]")
    parser.add_argument("--threads", type=int, default=1, help="Taichi CPU threads per case")
    parser.add_argument("--rate", type=float, default=60.0, help="path sample rate [Hz] (default 60)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--merge", nargs="+", type=Path, default=None, metavar="DIR",
                        help="copy the cycles of learning-set folders DIR into --out and merge their manifests")
    add_ray_arguments(parser)
    args = parser.parse_args(argv)
    if args.count < 1:
        parser.error(f"--count must be >= 1, got {args.count}")
    if args.merge:
        try:
            added = merge(Path(args.out), args.merge)
        except (ValueError, OSError) as exc:
            parser.exit(2, f"wheelloader: error: {exc}\n")
        print(f"{len(added)} cycles added to {args.out}: {' '.join(added)}")
        return 0
    cases = {c.name: c for c in design(args.count, args.seed)}
    if args.list:
        for c in cases.values():
            print(c.name, c.soil_family, f"phi {math.degrees(c.soil['phi']):.1f}", f"c {c.soil['cohesion']:.0f}",
                  f"slope {c.slope_deg:.0f}", f"control {c.control}", f"curl {c.curl_from}", f"T {c.duration}",
                  f"edge {c.edge_height}")
        return 0
    unknown = sorted(set(args.only or []) - set(cases))
    if unknown:
        parser.error(f"unknown case(s) {unknown}; see --list")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    def log(message: str) -> None:
        line = f"{time.strftime('%Y-%m-%d %H:%M:%S')} {message}"
        print(line, flush=True)
        with open(out / "progress.log", "a") as fh:
            fh.write(line + "\n")

    todo = [cases[n] for n in (args.only or cases)]
    pending = [c for c in todo if not (out / f"{c.name}.csv.xz").exists()]
    log(f"{len(todo) - len(pending)} of {len(todo)} cases done; {len(pending)} to dig (ray {args.ray})")
    units = [Unit(dig_unit, {"case": c, "resolution": args.resolution, "threads": args.threads, "rate": args.rate},
                  label=c.name, num_cpus=args.threads) for c in pending]

    def written(k: int, cyc: CycleLog) -> None:
        e = write_cycle(pending[k], cyc, out)
        log(f"{e['name']}: depth {e['max_depth_over_length']:.2f} L, max F_R {e['max_resultant_N']:.0f} N, "
            f"fill {e['final_fill_m3']:.3f} m^3, {e['wall_s']:.0f} s wall, {e['cpu_s']:.0f} s CPU, "
            f"load {e['loadavg_end']}")

    sweep = run_sweep(units, args.ray, ray_cpus=args.ray_cpus, progress=log, on_result=written)
    for failure in sweep.failures:
        log(f"FAILED {failure}\n{failure.traceback}")
    return 1 if sweep.failures else 0


if __name__ == "__main__":
    sys.exit(main())
