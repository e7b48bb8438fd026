"""``wheelloader dem``: the DEM (Yade) reference scenario and its shipped data set.

Subcommands: ``list`` (the reference cases and the command that regenerates each), ``reference``
(generate them, resumable), ``cycle`` (one scenario run into a directory), ``sanity`` (physical sanity
figures of a reference directory).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from wheelloader.ray_mode import add_ray_arguments

from .output import write_json
from .staging import OutputRun

#: Default reference directory, relative to the working directory (the repository root).
REFERENCE_DIR = Path("data") / "reference"


def _config_from_args(args: Any, soil: str) -> Any:
    from wheelloader.references.dem import DemConfig

    return DemConfig(soil=soil, scale=args.scale, slab_width=args.slab_width, radius=args.radius, young=args.young,
                     seed=args.seed, bulk_density=args.bulk_density, threads=args.threads)


def _print_indented(line: str) -> None:
    print("   " + line, flush=True)


def _cmd_reference(args: Any) -> int:
    from wheelloader.estimator import ParameterError
    from wheelloader.ray_mode import OFF
    from wheelloader.references.dem import reference_cases, run_reference, write_reference
    from wheelloader.references.dem.runner import find_yade
    from wheelloader.sweep import Unit, run_sweep

    find_yade()  # before any work: no Yade, one error line naming the install command
    cases = reference_cases()
    if args.only:
        known = {c.name: c for c in cases}
        unknown = [n for n in args.only if n not in known]
        if unknown:
            raise ParameterError(f"unknown reference case(s) {unknown}; choose from {sorted(known)}")
        cases = [known[n] for n in args.only]
    out = Path(args.out)
    # regenerating the shipped set is this command's purpose, so data/ is allowed; each finished case is
    # written as it completes (a Ctrl-C keeps them: resume with --skip-existing); the lock keeps a second
    # run out of the same directory
    run = OutputRun(force=True, allow_shipped=True)
    run.directory("--out", out, fresh=False)
    out.mkdir(parents=True, exist_ok=True)
    todo = []
    for k, case in enumerate(cases):
        if args.skip_existing and all((out / f"{s}.csv").exists() for s in case.file_stems()):
            print(f"[{k + 1}/{len(cases)}] {case.name}: exists, skipped", flush=True)
            continue
        todo.append(case)
    # one unit = one case (one Yade run of its cycles); each is written as soon as it finishes, so an
    # interrupted run keeps the finished cases (resume with --skip-existing)
    units = [Unit(run_reference, {"case": case, "cache_dir": args.cache_dir,
                                  "progress": _print_indented if args.ray == OFF else None},
                  label=f"{case.name} (soil={case.config.soil} paths={','.join(case.paths)})",
                  num_cpus=case.config.threads) for case in todo]
    with run:
        sweep = run_sweep(units, args.ray, ray_cpus=args.ray_cpus,
                          on_result=lambda k, result: write_reference(result, out),
                          progress=lambda line: print(line, flush=True))
    for failure in sweep.failures:
        print(f"FAILED {failure}\n{failure.traceback}", file=sys.stderr)
    if sweep.failures:
        print(f"{len(sweep.failures)} of {len(units)} cases failed (the others are written); re-run them with "
              "--only NAME ... or the whole set with --skip-existing", file=sys.stderr)
        return 1
    return 0


def _cmd_list(args: Any) -> int:
    from wheelloader.references.dem import reference_cases, regenerate_command

    for case in reference_cases():
        print(f"{case.name:24s} soil={case.config.soil:14s} paths={','.join(case.paths):12s} "
              f"seed={case.config.seed}  ->  {regenerate_command(case.name)}")
    return 0


def _cmd_cycle(args: Any) -> int:
    import numpy as np

    from wheelloader.references.dem import dual_cycle_paths, run_scenario, scenario_paths
    from wheelloader.references.dem.runner import find_yade

    find_yade()
    config = _config_from_args(args, args.soil)
    if args.path == "dual":
        paths = list(dual_cycle_paths(config))
    else:
        paths = [scenario_paths(config)[int(args.path) - 1]]
    outputs = OutputRun(force=True)
    out = outputs.directory("--out", args.out, fresh=False)
    with outputs:
        result = run_scenario(config, paths, outputs.staged(out), cache_dir=args.cache_dir)
        for i, log in enumerate(result.logs):
            log.save(outputs.staged(out) / f"cycle{i + 1}.csv", overwrite=True)
    for i, log in enumerate(result.logs):
        print(f"wrote {out / f'cycle{i + 1}.csv'} ({len(log)} samples, {log.metadata['particles']} particles, "
              f"mean F_R {np.mean(log.resultant):.1f} N, carried {log.metadata['carried_mass_end_load']:.2f} kg)")
    print(f"Yade run: {result.wall_s:.1f} s")
    return 0


def _cmd_sanity(args: Any) -> int:
    from wheelloader.estimator import ParameterError
    from wheelloader.references.dem import sanity_report

    data = Path(args.data)
    if not (data / "manifest.json").is_file():
        raise ParameterError(f"--data {data}: no manifest.json there (run from the repository root, or pass the "
                             "reference directory)")
    _check_dem_manifest(data / "manifest.json")
    run = OutputRun(force=args.force, inputs=[data / "manifest.json"], input_dirs=[data])
    run.file("--json", args.json)
    with run:
        report = sanity_report(data)
        write_json(run.staged(args.json), report)
    for line in sanity_summary(report, data):
        print(line)
    print(f"full report written to {args.json}")
    return 0


def _check_dem_manifest(path: Path) -> None:
    """Refuse a manifest that is not a DEM reference set's (an MPM set has no raw Yade files)."""
    from wheelloader.estimator import ParameterError
    from wheelloader.estimator.jsonable import read_json

    manifest = read_json(path)
    kind = manifest.get("format") if isinstance(manifest, dict) else None
    if kind != "wheelloader.dem-reference":
        raise ParameterError(f"--data {path.parent}: {path.name} is not a DEM reference set's (format {kind!r}, "
                             "expected 'wheelloader.dem-reference')")
    cycles = manifest.get("cycles")
    if not isinstance(cycles, list) or not all(isinstance(c, dict) and {"name", "csv", "raw_csv"} <= set(c)
                                               for c in cycles):
        raise ParameterError(f"--data {path.parent}: {path.name} must list cycles with name, csv and raw_csv")


def sanity_summary(report: dict[str, Any], data: Path | str) -> list[str]:
    """A few lines of the sanity report (:func:`~wheelloader.references.dem.sanity_report`) for a person."""
    cycles = report.get("cycles", {})
    f = report.get("filter", {})
    lines = [f"DEM reference {data}: {len(cycles)} cycles (filter {f.get('kind', '?')}, "
             f"sigma {f.get('sigma_s', float('nan')):g} s)"]
    zero = {n: c["no_contact_zero_fraction"] for n, c in cycles.items() if "no_contact_zero_fraction" in c}
    if zero:
        worst = min(zero, key=zero.get)
        exceptions = len(report.get("zero force out of contact", {}))
        lines.append(f"force exactly zero out of contact: in {min(zero.values()):.0%}-{max(zero.values()):.0%} of "
                     f"the contact-free windows per cycle ({len(zero) - exceptions} of {len(zero)} cycles: all; "
                     f"lowest {worst})")
    depth = report.get("depth", {})
    if depth:
        lines.append("mean F_R grows with mean depth over paths 1-4: "
                     + ", ".join(f"{soil} {'yes' if d['monotone'] else 'NO'}" for soil, d in depth.items()))
    mass = report.get("mass")
    if mass:
        lines.append(f"carried mass / (carved volume x bulk density): {mass['min_ratio']:.2f}-{mass['max_ratio']:.2f} "
                     f"({'within' if mass['within_tolerance'] else 'OUTSIDE'} +-{mass['tolerance']:.0%})")
    for label, ratios in report.items():
        if isinstance(ratios, dict) and "mean_resultant_ratio" in ratios:
            lines.append(f"{label}: mean F_R x{ratios['mean_resultant_ratio']:.2f}, "
                         f"carried mass x{ratios['carried_mass_ratio']:.2f}")
    return lines


def register(subparsers: Any) -> None:
    """Add the ``dem`` command (subcommands list, reference, cycle, sanity)."""
    parser = subparsers.add_parser("dem", help="DEM (Yade) reference scenario and its shipped data set",
                                   description="The DEM (Yade) reference: list the shipped reference cases, "
                                               "regenerate them (resumable), run one scenario, or report the "
                                               "data's sanity figures.")
    parser.set_defaults(func=lambda args: parser.print_help() or 2)
    sub = parser.add_subparsers(title="dem commands", metavar="SUBCOMMAND")
    p = sub.add_parser("reference", help="(re)generate the shipped reference cycles",
                       description="Regenerate the shipped DEM reference cycles in Yade (resumable: each finished "
                                   "case is written at once; --skip-existing resumes).")
    p.add_argument("--only", nargs="+", metavar="NAME", help="case names (see 'list'); default: all")
    p.add_argument("--out", default=str(REFERENCE_DIR),
                   help="output directory (default: %(default)s, relative to the working directory)")
    p.add_argument("--cache-dir", default=None,
                   help="settled-pile cache directory (default ~/.cache/wheelloader/dem)")
    p.add_argument("--skip-existing", action="store_true", help="skip cases whose files exist (resume)")
    add_ray_arguments(p)
    p.set_defaults(func=_cmd_reference)
    p = sub.add_parser("list", help="list the reference cases and their regeneration commands")
    p.set_defaults(func=_cmd_list)
    p = sub.add_parser("cycle", help="run one scenario and write its cycle log(s)",
                       description="Run one DEM scenario in Yade and write its cycle log(s) (CSV + JSON sidecar) "
                                   "into --out as cycle1.csv, cycle2.csv, ...")
    p.add_argument("--soil", default="gravel", choices=["gravel", "sand", "dirt", "modified_sand"],
                   help="soil of the particles (default: %(default)s)")
    p.add_argument("--path", default="1", choices=["1", "2", "3", "4", "dual"],
                   help="the paper's path 1-4, or 'dual': two cycles on the same pile (default: %(default)s)")
    p.add_argument("--out", required=True, help="output directory (made if missing; files of the same name in it "
                                                "are replaced)")
    p.add_argument("--scale", type=float, default=0.6,
                   help="geometric scale of pile, bucket and paths against the 1 m pile [-] (default: %(default)s)")
    p.add_argument("--slab-width", type=float, default=0.35, help="slab and bucket width in y [m] "
                                                                  "(default: %(default)s)")
    p.add_argument("--radius", type=float, default=0.03, help="mean particle radius [m] (default: %(default)s)")
    p.add_argument("--young", type=float, default=5e7,
                   help="Young's modulus of particles and bucket [Pa] (default: %(default)g)")
    p.add_argument("--bulk-density", type=float, default=None,
                   help="target bulk density of the soil [kg/m^3] (default: the soil's own)")
    p.add_argument("--seed", type=int, default=1, help="seed of the particle deposition (default: %(default)s)")
    p.add_argument("--threads", type=int, default=1,
                   help="Yade OpenMP threads; 1 is bit-reproducible (default: %(default)s)")
    p.add_argument("--cache-dir", default=None,
                   help="settled-pile cache directory (default ~/.cache/wheelloader/dem)")
    p.set_defaults(func=_cmd_cycle)
    p = sub.add_parser("sanity", help="physical sanity checks of a reference directory (summary; full report "
                                      "as JSON)")
    p.add_argument("--data", default=str(REFERENCE_DIR),
                   help="reference directory (default: %(default)s, relative to the working directory)")
    p.add_argument("--json", default="sanity.json",
                   help="where the full report (every cycle's figures) goes (default: %(default)s)")
    p.add_argument("--force", "--overwrite", dest="force", action="store_true",
                   help="replace an existing --json (never a file of --data)")
    p.set_defaults(func=_cmd_sanity)
