"""Generate the shipped MPM reference set (``data/mpm``): resumable, one cycle at a time.

::

    python -m wheelloader.references.mpm.generate --out data/mpm            # everything not yet done
    python -m wheelloader.references.mpm.generate --out data/mpm --only gravel_path1
    python -m wheelloader.references.mpm.generate --list

Cases (in generation order): gravel paths 1-4 of :func:`~wheelloader.estimator.paper_paths`, a gravel
dual-cycle pair (Fig. 9: path 1, then a path reaching 0.3 m further in, dug on the surface the first
left; the bucket is emptied between them and the second cycle starts from fresh, stress-free-settled
soil under the carved surface), modified sand, dirt and sand paths 1-4, and gravel path 1 on a 25 deg
pile. Soils: :func:`~wheelloader.estimator.preset` (Table 2 values: density, phi, C, C_a, delta; the
Bekker parameters are unused). Pile: :meth:`Pile.trapezoid` (1 m high, 30 deg; its toe at x = 0).

Each cycle is written as ``NAME.csv`` + ``NAME.json`` (:class:`~wheelloader.estimator.CycleLog`) and
entered in ``manifest.json`` with the command that regenerates it, its cost and its settings. A case
whose files and manifest entry exist is skipped; progress lines go to ``OUT/progress.log``. Cases run as
units of :mod:`wheelloader.sweep` (``--ray local``, the default with Ray installed: Ray tasks, one per free
CPU, each with ``--threads`` CPUs; ``--ray off``: one after the other).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wheelloader.estimator import BucketPath, CycleLog, Pile, bezier_path, paper_paths
from wheelloader.provenance import machine_info
from wheelloader.ray_mode import add_ray_arguments
from wheelloader.sweep import Unit, run_sweep

from .plant import DEFAULT_RESOLUTION, MPMPlant

FORMAT_NAME = "wheelloader.mpm-reference"
SOILS = ("gravel", "modified_sand", "dirt", "sand")
SECOND_SLOPE = math.radians(25.0)


@dataclass(frozen=True)
class Case:
    """One reference case: a soil, a pile and one path (or two for a dual cycle)."""

    name: str
    soil: str
    paths: tuple[str, ...]
    slope: float = math.radians(30.0)

    def stems(self) -> list[str]:
        return [self.name] if len(self.paths) == 1 else [f"{self.name}_cycle{i + 1}" for i in range(len(self.paths))]

    def pile(self) -> Pile:
        return Pile.trapezoid(angle=self.slope)


def dual_second_path() -> BucketPath:
    """Second cycle of the dual pair: path 1's start, reaching 0.3 m further in (as ``dem.dual_cycle_paths``)."""
    return bezier_path((-0.10, 0.03), (1.50, 0.05), (1.75, 1.20), curl_from=0.6, name="dual cycle 2")


def path_by_key(key: str) -> BucketPath:
    """``path1``..``path4`` (paper_paths), ``dual1`` (path 1) or ``dual2``."""
    if key.startswith("path") and key[4:] in ("1", "2", "3", "4"):
        return paper_paths()[int(key[4:]) - 1]
    if key == "dual1":
        return replace_name(paper_paths()[0], "dual cycle 1")
    if key == "dual2":
        return dual_second_path()
    raise ValueError(f"unknown path key {key!r}")


def replace_name(path: BucketPath, name: str) -> BucketPath:
    return BucketPath(path.t, path.x, path.z, path.blade_angle, name)


def cases() -> list[Case]:
    """The reference set in generation order."""
    out = [Case(f"gravel_path{k}", "gravel", (f"path{k}",)) for k in range(1, 5)]
    out.append(Case("gravel_dual", "gravel", ("dual1", "dual2")))
    for soil in SOILS[1:]:
        out += [Case(f"{soil}_path{k}", soil, (f"path{k}",)) for k in range(1, 5)]
    out.append(Case("gravel_slope25_path1", "gravel", ("path1",), slope=SECOND_SLOPE))
    return out


def regenerate_command(name: str, resolution: float) -> str:
    extra = "" if resolution == DEFAULT_RESOLUTION else f" --resolution {resolution:g}"
    return f"python -m wheelloader.references.mpm.generate --out data/mpm --only {name}{extra}"


def _manifest(out: Path) -> dict[str, Any]:
    fname = out / "manifest.json"
    if fname.exists():
        return json.loads(fname.read_text())
    return {"format": FORMAT_NAME, "version": 1, "cycles": []}


def _write_manifest(out: Path, manifest: dict[str, Any]) -> None:
    order = {c.name: k for k, c in enumerate(cases())}
    manifest["cycles"] = sorted(manifest["cycles"], key=lambda e: (order.get(e["case"], 999), e["cycle"]))
    manifest["notes"] = ("Plane-strain MPM cycles (wheelloader.references.mpm). Forces [N] and fill [m^3] for the "
                         "default 1 m wide bucket; pile = Pile.trapezoid (toe at x = 0). Regenerate a case with "
                         "its 'command'. Filter for comparisons: Gaussian sigma 0.1 s.")
    tmp = out / "manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=1))
    tmp.replace(out / "manifest.json")


def done(out: Path, case: Case) -> bool:
    """Whether every cycle of ``case`` has its files and manifest entry."""
    names = {e["name"] for e in _manifest(out)["cycles"]}
    return all((out / f"{s}.csv").exists() and (out / f"{s}.json").exists() and s in names for s in case.stems())


def existing_cycles(case: Case, out: Path, seed: int = 0) -> dict[str, CycleLog]:
    """The cycles of ``case`` already written in ``out`` (by stem), and for a dual pair whose first cycle is
    path 1 on the fresh pile, ``SOIL_path1`` (the same run) under that name; :func:`dig_case` reuses them."""
    found = {}
    for key, stem in zip(case.paths, case.stems(), strict=True):
        csv = out / f"{stem}.csv"
        same = out / f"{case.soil}_path1.csv"
        if csv.exists() and csv.with_suffix(".json").exists():
            found[stem] = CycleLog.load(csv)
        elif key == "dual1" and case.slope == math.radians(30.0) and same.exists() and seed == 0:
            found[same.stem] = CycleLog.load(same)
    return found


def dig_case(case: Case, plant: MPMPlant, seed: int = 0, existing: dict[str, CycleLog] | None = None,
             log=print) -> list[CycleLog]:
    """The cycles of ``case``, each with its metadata (name, case, cycle, regenerate command, load): reused
    from ``existing`` (:func:`existing_cycles`) where there, else dug with ``plant``. Writes nothing."""
    existing = existing or {}
    pile = case.pile()
    cycles = []
    for i, (key, stem) in enumerate(zip(case.paths, case.stems(), strict=True)):
        same = f"{case.soil}_path1"
        if stem in existing:
            cyc = existing[stem]
            log(f"{stem}: exists, reused")
        elif key == "dual1" and case.slope == math.radians(30.0) and same in existing and seed == 0:
            # the first cycle of the pair is path 1 on the fresh pile: the same run as SOIL_path1
            cyc = existing[same]
            cyc = CycleLog(cyc.path, cyc.tangential, cyc.normal, cyc.pile, cyc.bucket, cyc.fill_volume,
                           cyc.measured_load, cyc.pile_after,
                           dict(cyc.metadata, name=stem, case=case.name, cycle=i + 1, copied_from=f"{same}.csv"))
            log(f"{stem}: copied from {same}.csv (the same path, pile, soil and seed)")
        else:
            load = machine_info()["loadavg_1_5_15min"]
            log(f"{stem}: start ({case.soil}, {key}, dx {plant.settings.resolution:g} m, load {load})")
            cyc = plant.dig(path_by_key(key), pile, case.soil, seed=seed)
            cmd = regenerate_command(case.name, plant.settings.resolution)
            cyc = CycleLog(cyc.path, cyc.tangential, cyc.normal, cyc.pile, cyc.bucket, cyc.fill_volume,
                           cyc.measured_load, cyc.pile_after,
                           dict(cyc.metadata, name=stem, case=case.name, cycle=i + 1, regenerate=cmd,
                                loadavg_start=load, loadavg_end=machine_info()["loadavg_1_5_15min"]))
            log(f"{stem}: done in {cyc.metadata['wall_s']:.0f} s, max F_R {max(cyc.resultant):.0f} N, "
                f"fill {cyc.fill_volume[-1]:.3f} m^3")
        cycles.append(cyc)
        pile = cyc.pile_after
    return cycles


def write_case(case: Case, cycles: Sequence[CycleLog], out: Path) -> list[dict[str, Any]]:
    """Save the cycles of ``case`` in ``out`` (``NAME.csv`` + ``NAME.json``) and enter them in the manifest."""
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for i, (key, stem, cyc) in enumerate(zip(case.paths, case.stems(), cycles, strict=True)):
        csv = out / f"{stem}.csv"
        if not (csv.exists() and csv.with_suffix(".json").exists()):
            cyc.save(csv, overwrite=True)
        m = cyc.metadata
        entries.append({
            "name": stem, "case": case.name, "csv": f"{stem}.csv", "soil": case.soil, "path": key,
            "path_name": cyc.path.name, "cycle": i + 1, "cycles_in_run": len(case.paths),
            "pile": {"kind": "trapezoid", "angle_deg": math.degrees(case.slope), "height": 1.0,
                     "start": "Pile.trapezoid" if i == 0 else f"pile_after of {case.stems()[i - 1]}"},
            "seed": m.get("seed"), "resolution": m.get("resolution"), "particles": m.get("particles"),
            "steps": m.get("steps"), "wall_s": m.get("wall_s"), "settle_wall_s": m.get("settle_wall_s"),
            "taichi_threads": m.get("taichi_threads"), "loadavg_start": m.get("loadavg_start"),
            "loadavg_end": m.get("loadavg_end"), "mass_balance": m.get("mass_balance"),
            "settings": m.get("settings"), "continuum": m.get("continuum"), "command": m.get("regenerate"),
        })
    manifest = _manifest(out)
    names = {e["name"] for e in entries}
    manifest["cycles"] = [e for e in manifest["cycles"] if e["name"] not in names] + entries
    manifest["generated_with"] = {k: v for k, v in machine_info().items() if k != "loadavg_1_5_15min"}
    _write_manifest(out, manifest)
    return entries


def generate_case(case: Case, out: Path, plant: MPMPlant, seed: int = 0, log=print) -> list[dict[str, Any]]:
    """Run ``case`` (skipping cycles already written) and enter its cycles in the manifest."""
    out.mkdir(parents=True, exist_ok=True)
    return write_case(case, dig_case(case, plant, seed, existing_cycles(case, out, seed), log), out)


@functools.lru_cache(maxsize=2)
def _process_plant(resolution: float, threads: int) -> MPMPlant:
    """One plant per process and settings (Taichi is initialised once per process)."""
    return MPMPlant(resolution, threads=threads)


def _timestamped(message: str) -> None:
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {message}", flush=True)


def dig_case_unit(case: Case, resolution: float, threads: int, seed: int, existing: dict[str, CycleLog],
                  log=None) -> list[CycleLog]:
    """:func:`dig_case` as a sweep unit (:mod:`wheelloader.sweep`): builds the plant in the process it runs in;
    ``log`` defaults to timestamped lines on stdout (a Ray worker's reach the driver's terminal)."""
    return dig_case(case, _process_plant(resolution, threads), seed, existing, log=log or _timestamped)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m wheelloader.references.mpm.generate",
                                     description="Generate the MPM reference set (resumable).")
    parser.add_argument("--out", default="data/mpm", help="output directory (default data/mpm)")
    parser.add_argument("--only", nargs="*", default=None, help="case names (default: all not yet done)")
    parser.add_argument("--resolution", type=float, default=DEFAULT_RESOLUTION, help="grid cell size [m]")
    parser.add_argument("--threads", type=int, default=1, help="Taichi CPU threads")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--force", action="store_true", help="re-run cases that are done")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    add_ray_arguments(parser)
    args = parser.parse_args(argv)
    all_cases = {c.name: c for c in cases()}
    if args.list:
        for c in all_cases.values():
            print(c.name, c.soil, " ".join(c.paths), f"slope {math.degrees(c.slope):.0f} deg")
        return 0
    unknown = sorted(set(args.only or []) - set(all_cases))
    if unknown:
        parser.error(f"unknown case(s) {unknown}; see --list")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    progress = out / "progress.log"

    def log(message: str) -> None:
        line = f"{time.strftime('%Y-%m-%d %H:%M:%S')} {message}"
        print(line, flush=True)
        with open(progress, "a") as fh:
            fh.write(line + "\n")

    todo = [all_cases[n] for n in args.only] if args.only else list(all_cases.values())
    pending = []
    for case in todo:
        if done(out, case) and not args.force:
            log(f"{case.name}: done, skipped")
            continue
        if args.force:
            for stem in case.stems():
                for suffix in (".csv", ".json"):
                    (out / f"{stem}{suffix}").unlink(missing_ok=True)
        pending.append(case)
    # one sweep unit per case (serial, or Ray tasks with --ray); each case is written here as soon as it
    # finishes, so an interrupted run resumes where it stopped. The dual pairs go second: their first cycle
    # is copied from SOIL_path1 once that exists.
    waves = [[c for c in pending if not c.name.endswith("_dual")], [c for c in pending if c.name.endswith("_dual")]]
    failed = []
    for wave in (w for w in waves if w):
        units = [Unit(dig_case_unit, {"case": case, "resolution": args.resolution, "threads": args.threads,
                                      "seed": args.seed, "existing": existing_cycles(case, out, args.seed),
                                      "log": log if args.ray == "off" else None},
                      label=case.name, num_cpus=args.threads) for case in wave]
        sweep = run_sweep(units, args.ray, ray_cpus=args.ray_cpus, progress=log,
                          on_result=lambda k, cycles, wave=wave: write_case(wave[k], cycles, out))
        failed += sweep.failures
    for failure in failed:
        log(f"FAILED {failure}\n{failure.traceback}")
    if failed:
        log(f"{len(failed)} case(s) failed: {', '.join(f.label for f in failed)}; the others are written, "
            "run again to retry them")
        return 1
    log("all requested cases done")
    return 0


if __name__ == "__main__":
    sys.exit(main())
