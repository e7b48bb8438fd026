"""Verification of the plane-strain MPM reference plant: closed forms, convergence, seeds, mass balance.

Parts (each writes ``OUT/part_<name>.json``; ``--report`` assembles ``OUT/mpm_verification.json`` and
``OUT/mpm_verification.png`` from whatever parts exist)::

    blade     vertical blade vs the McKyes passive wedge, 3 depths x 2 soils (target +-10 %)
    wall      smooth wall: at rest (vs 1 - sin phi) and pushed (vs Rankine passive) (target +-15 %)
    column    granular column collapse run-out at three resolutions vs Lube et al. 2005 (quasi-2-D) and
              the true-2-D rod experiments of arXiv:1512.05180
    cycle     the default bucket cycle at three resolutions (finest two <= 7 % filtered F_R) and at
              three seeds of the default resolution (spread <= 5 %), with the mass balance
    newton    the blade (phi 30, delta 20 deg) in Newton's implicit MPM (optional extra mpm-newton) beside
              ours, same window, both against McKyes (a cross-check with an existing engine)

Run e.g. ``python benchmarks/mpm_verification.py --out results/mpm --parts blade wall column`` and
later ``--parts cycle``; ``--report`` only assembles. Taichi runs on ``--threads`` threads (default 1).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from wheelloader.provenance import machine_info

PARTS = ("blade", "wall", "column", "cycle", "newton")
SIGMA_S = 0.1
BLADE_DEPTHS = (0.10, 0.15, 0.20)
BLADE_CELLS = 10.0
NEWTON_DEPTHS = (0.10, 0.15, 0.20)
WALL_HEIGHT = 0.3
WALL_DX = 0.015
COLUMN_RATIOS = (0.5, 1.0, 3.0)
COLUMN_DXS = (0.02, 0.01, 0.005)
CYCLE_RESOLUTIONS = (0.03, 0.02, 0.015)
CYCLE_SEEDS = (0, 1, 2)


def git_commit() -> str | None:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                             cwd=Path(__file__).resolve().parent)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, cwd=Path(__file__).resolve().parent).stdout.strip()
        return out.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return None


def blade_soils() -> dict:
    from wheelloader.references.mpm import ContinuumSoil

    a = ContinuumSoil(1600.0, math.radians(30.0), wall_friction_angle=math.radians(20.0))
    return {"phi30_delta20": a,
            "phi30_delta20_c1000_ca500": ContinuumSoil(1600.0, math.radians(30.0), cohesion=1000.0,
                                                       wall_friction_angle=math.radians(20.0), adhesion=500.0)}


#: Reported beside the criterion rows, not part of it: the "dirt" preset (phi 40 deg, c 2.1 kPa, c_a 2.5 kPa).
EXTRA_BLADE_SOILS = ("dirt",)


def blade_summary(res, depth: float, soil) -> dict:
    """One blade run (Taichi's or Newton's) against McKyes: means over 0.5-1.0 d of travel (and 0.25-0.5 d),
    flat and with the run's own heap as surcharge, and the time series."""
    from wheelloader.references.mpm.verification import mckyes_blade, mckyes_blade_with_heap

    travel = res.extra["travel"]
    window = (travel >= 0.5 * depth) & (travel <= 1.0 * depth)
    horizontal = float(-np.mean(res.force[window, 0]))
    vertical = float(np.mean(res.force[window, 1]))
    ref = mckyes_blade(depth, soil)
    # the heap on the wedge, averaged over the same window, as McKyes' surcharge q
    heap = np.mean(res.extra["heap_mass"][window], axis=0)
    edges = res.extra["heap_bin_edges"]
    cumulative = np.concatenate([[0.0], np.cumsum(heap)])
    heaped = mckyes_blade_with_heap(depth, soil, lambda length: float(np.interp(length, edges, cumulative)))
    early = (travel >= 0.25 * depth) & (travel <= 0.5 * depth)
    horizontal_early = float(-np.mean(res.force[early, 0]))
    return {"horizontal": horizontal, "vertical": vertical, "horizontal_0.25_0.5d": horizontal_early,
            "ratio_0.25_0.5d": horizontal_early / ref["horizontal"],
            "mckyes_horizontal": ref["horizontal"], "ratio_flat": horizontal / ref["horizontal"],
            "mckyes_heap_horizontal": heaped["horizontal"], "heap_surcharge": heaped["surcharge"],
            "heap_wedge_length": heaped["wedge_length"], "heap_mass": float(heap.sum()),
            "ratio": horizontal / heaped["horizontal"],
            "vertical_over_horizontal": vertical / horizontal,
            "tan_delta": math.tan(soil.wall_friction_angle), "particles": res.particles,
            "steps": res.steps, "wall_s": res.wall_s,
            "travel": travel.tolist(), "fx": res.force[:, 0].tolist(), "fz": res.force[:, 1].tolist()}


def part_blade(args) -> dict:
    from wheelloader.references.mpm import ContinuumSoil
    from wheelloader.references.mpm.verification import run_blade

    rows = []
    soils = [(name, soil, True) for name, soil in blade_soils().items()]
    soils += [(name, ContinuumSoil.from_soil(name), False) for name in EXTRA_BLADE_SOILS]
    for name, soil, criterion in soils:
        for depth in BLADE_DEPTHS:
            dx = depth / BLADE_CELLS
            res = run_blade(depth, soil, dx, threads=args.threads)
            row = blade_summary(res, depth, soil)
            rows.append({"soil": name, "criterion": criterion, "depth": depth, "dx": dx, **row,
                         "guard_impulse_share": res.extra["guard_impulse_share"]})
            progress(args, f"blade {name} d={depth}: {row['horizontal']:.0f} N/m vs McKyes "
                           f"{row['mckyes_horizontal']:.0f} flat ({row['ratio_flat']:.3f}), "
                           f"{row['mckyes_heap_horizontal']:.0f} with the measured heap q={row['heap_surcharge']:.0f} "
                           f"Pa ({row['ratio']:.3f}), {res.wall_s:.0f} s")
    return {"rows": rows, "window": "mean over 0.5-1.0 depth of travel (ratio, ratio_flat); 0.25-0.5 depth "
                                    "(ratio_0.25_0.5d, flat surface)",
            "reference": "ratio: McKyes with the surcharge q of the soil heaped on the wedge, measured in the run "
                         "over the same window (mckyes_blade_with_heap); ratio_flat: McKyes on a flat surface (q = 0)",
            "cells_over_cut": BLADE_CELLS,
            "speed": 0.2}


def part_newton(args) -> dict:
    """The first blade soil (phi 30, delta 20 deg) in Newton's implicit MPM and in ours, same window."""
    from importlib.metadata import version

    from wheelloader.references.mpm.newton_blade import NEWTON_INSTALL_HINT, NewtonBladeSettings, run_newton_blade
    from wheelloader.references.mpm.verification import run_blade

    name, soil = next(iter(blade_soils().items()))
    settings = NewtonBladeSettings()
    rows = []
    for depth in args.newton_depths:
        dx = depth / BLADE_CELLS
        res_newton = run_newton_blade(depth, soil, dx, settings=settings)
        res_taichi = run_blade(depth, soil, dx, threads=args.threads)
        newton_row = blade_summary(res_newton, depth, soil)
        newton_row.update(floor_reaction_over_weight=res_newton.extra["floor_reaction_over_weight"],
                          finite=res_newton.extra["finite"], slab_width=res_newton.extra["width"])
        taichi_row = blade_summary(res_taichi, depth, soil)
        rows.append({"soil": name, "depth": depth, "dx": dx, "newton": newton_row, "taichi": taichi_row,
                     "newton_over_taichi": newton_row["horizontal"] / taichi_row["horizontal"]})
        # each depth costs minutes: keep what is done if the part is stopped
        (Path(args.out) / "part_newton.partial.json").write_text(json.dumps({"rows": rows}, indent=1))
        progress(args, f"newton {name} d={depth}: Newton {newton_row['horizontal']:.0f} N/m "
                       f"({newton_row['ratio_flat']:.3f} flat, {newton_row['ratio']:.3f} heap, "
                       f"{res_newton.wall_s:.0f} s), Taichi {taichi_row['horizontal']:.0f} N/m "
                       f"({taichi_row['ratio_flat']:.3f} flat, {taichi_row['ratio']:.3f} heap, "
                       f"{res_taichi.wall_s:.0f} s)")
    return {"rows": rows, "window": "mean over 0.5-1.0 depth of travel", "cells_over_cut": BLADE_CELLS,
            "speed": 0.2, "newton_settings": dict(vars(settings)),
            "versions": {"newton": version("newton"), "warp-lang": version("warp-lang")},
            "install": NEWTON_INSTALL_HINT,
            "model": "Newton SolverImplicitMPM, Warp CPU device: a slab settings.cells_across voxels wide between "
                     "frictionless walls; Drucker-Prager mu = sin(phi), no dilatancy; blade collider Coulomb "
                     "friction tan(delta); forces per metre of slab width"}


def part_wall(args) -> dict:
    from wheelloader.references.mpm.verification import at_rest_force, rankine_passive, run_wall

    rows = []
    for name, soil in blade_soils().items():
        res = run_wall(WALL_HEIGHT, soil, WALL_DX, push=0.06, speed=0.05, threads=args.threads)
        disp = res.extra["displacement"]
        rest_window = (res.times > 0.45) & (res.times < 0.6)
        at_rest = float(-np.mean(res.force[rest_window, 0]))
        passive_window = disp >= 0.04
        passive = float(-np.mean(res.force[passive_window, 0]))
        k0 = soil.at_rest_ratio
        rows.append({"soil": name, "height": WALL_HEIGHT, "dx": WALL_DX, "at_rest": at_rest,
                     "at_rest_reference": at_rest_force(WALL_HEIGHT, soil), "at_rest_ratio_used": k0,
                     "at_rest_over_reference": at_rest / at_rest_force(WALL_HEIGHT, soil),
                     "passive": passive, "rankine_passive": rankine_passive(WALL_HEIGHT, soil),
                     "passive_over_rankine": passive / rankine_passive(WALL_HEIGHT, soil),
                     "passive_window": "wall displacement 0.04-0.06 m (13-20 % of H)",
                     "particles": res.particles, "wall_s": res.wall_s,
                     "displacement": disp.tolist(), "fx": res.force[:, 0].tolist()})
        progress(args, f"wall {name}: at rest {at_rest:.0f} vs {at_rest_force(WALL_HEIGHT, soil):.0f}, passive "
                       f"{passive:.0f} vs Rankine {rankine_passive(WALL_HEIGHT, soil):.0f}, {res.wall_s:.0f} s")
    return {"rows": rows}


def part_column(args) -> dict:
    from wheelloader.references.mpm import ContinuumSoil
    from wheelloader.references.mpm.verification import (
        column_runout_scaling,
        column_runout_true_2d,
        run_column_collapse,
    )

    soil = ContinuumSoil(1600.0, math.radians(30.0))
    rows = []
    for a in COLUMN_RATIOS:
        for dx in COLUMN_DXS:
            res = run_column_collapse(a, soil, dx, threads=args.threads)
            ref = column_runout_scaling(a)
            true_2d = column_runout_true_2d(a)
            bounds = [float(ref["lube"])] + ([true_2d] if true_2d is not None else [])
            rows.append({"aspect_ratio": a, "dx": dx, "cells_across": 0.2 / dx, "runout": res.extra["runout"],
                         "lube_2005": ref["lube"], "lube_regime": ref["regime"], "true_2d_2015": true_2d,
                         "over_lube": res.extra["runout"] / ref["lube"],
                         "within_published_envelope": (min(bounds) * 0.9 <= res.extra["runout"]
                                                       <= max(bounds) * 1.1),
                         "final_kinetic_energy": res.extra["kinetic_energy"], "particles": res.particles,
                         "wall_s": res.wall_s})
            progress(args, f"column a={a} dx={dx}: run-out {res.extra['runout']:.2f} vs Lube {ref['lube']:.2f}"
                           f" / true 2-D {true_2d if true_2d is None else round(true_2d, 2)}, {res.wall_s:.0f} s")
    return {"rows": rows, "soil": soil.to_dict(), "dxs": list(COLUMN_DXS), "width": 0.2,
            "envelope": "between the quasi-2-D fit of Lube et al. 2005 and the true-2-D fit of arXiv:1512.05180, "
                        "+-10 % (Lube alone below a = 0.65)"}


def _filtered_resultant(log) -> np.ndarray:
    from scipy.ndimage import gaussian_filter1d

    rate = 1.0 / float(np.median(np.diff(log.path.t)))
    ft = gaussian_filter1d(np.asarray(log.tangential), SIGMA_S * rate, mode="nearest")
    fn = gaussian_filter1d(np.asarray(log.normal), SIGMA_S * rate, mode="nearest")
    return np.hypot(ft, fn)


def relative_rmse(a: np.ndarray, b: np.ndarray) -> float:
    """RMS of a - b over the mean magnitude of b [%] (the project's RMSE percentage)."""
    return float(100.0 * np.sqrt(np.mean((a - b) ** 2)) / np.mean(np.abs(b)))


def part_cycle(args) -> dict:
    from wheelloader.estimator import Pile, default_path
    from wheelloader.references import make_plant
    from wheelloader.references.mpm import DEFAULT_RESOLUTION

    pile, path = Pile.trapezoid(), default_path()
    runs = {}
    from wheelloader.estimator import CycleLog

    # the default-resolution seed-0 run last: the reference set's SOIL_path1 is the same run (--reuse)
    plan = [(dx, 0) for dx in CYCLE_RESOLUTIONS if dx != DEFAULT_RESOLUTION]
    plan += [(DEFAULT_RESOLUTION, s) for s in CYCLE_SEEDS if s != 0] + [(DEFAULT_RESOLUTION, 0)]
    for dx, seed in plan:
        key = f"dx{dx:g}_seed{seed}"
        cache = Path(args.out) / f"cycle_{key}.csv"
        shipped = Path(args.reuse) / f"{args.soil}_path1.csv" if args.reuse else None
        if cache.exists():
            log = CycleLog.load(cache)
        elif (shipped is not None and shipped.exists() and dx == DEFAULT_RESOLUTION and seed == 0
              and CycleLog.load(shipped).metadata.get("seed") == 0):
            log = CycleLog.load(shipped)
            log.save(cache, overwrite=True)
            progress(args, f"cycle {key}: reused {shipped}")
        else:
            log = make_plant("mpm", resolution=dx, threads=args.threads).dig(path, pile, args.soil, seed=seed)
            log.save(cache, overwrite=True)
        runs[key] = log
        progress(args, f"cycle {key}: {log.metadata['wall_s']:.0f} s, {log.metadata['particles']} particles")
    out = {"soil": args.soil, "path": path.name, "sigma_s": SIGMA_S, "runs": {}}
    for key, log in runs.items():
        m = log.metadata
        out["runs"][key] = {"resolution": m["resolution"], "seed": m["seed"], "particles": m["particles"],
                            "steps": m["steps"], "wall_s": m["wall_s"], "mass_balance": m["mass_balance"],
                            "guard_corrections": m["guard_corrections"], "t": log.path.t.tolist(),
                            "F_T": log.tangential.tolist(), "F_N": log.normal.tolist(),
                            "fill": log.fill_volume.tolist(), "F_R_filtered": _filtered_resultant(log).tolist(),
                            "mean_F_R": float(np.mean(log.resultant))}
    res = [f"dx{dx:g}_seed0" for dx in CYCLE_RESOLUTIONS]
    fr = {k: _filtered_resultant(runs[k]) for k in runs}
    raw = {k: runs[k].resultant for k in runs}
    out["convergence"] = {
        f"{a} vs {b}": {"filtered_percent": relative_rmse(fr[a], fr[b]), "raw_percent": relative_rmse(raw[a], raw[b])}
        for a, b in zip(res[:-1], res[1:], strict=True)}
    seeds = [f"dx{DEFAULT_RESOLUTION:g}_seed{s}" for s in CYCLE_SEEDS]
    mean_fr = np.array([np.mean(fr[k]) for k in seeds])
    out["seed_spread"] = {
        "mean_F_R_filtered": mean_fr.tolist(),
        "spread_percent": float(100.0 * (mean_fr.max() - mean_fr.min()) / mean_fr.mean()),
        "pairwise_filtered_percent": [relative_rmse(fr[a], fr[b]) for i, a in enumerate(seeds) for b in seeds[i + 1:]],
    }
    balance = runs[seeds[0]].metadata["mass_balance"]
    out["mass_balance"] = dict(balance, fill_over_net_removed=balance["fill_area_end"] / balance["net_area_removed"],
                               carried_over_net_removed=balance["detached_area_end"] / balance["net_area_removed"])
    return out


def progress(args, message: str) -> None:
    line = f"{time.strftime('%H:%M:%S')} {message}"
    print(line, flush=True)
    if args.progress:
        with open(args.progress, "a") as fh:
            fh.write(line + "\n")


def report(out_dir: Path) -> dict:
    parts = {}
    for name in PARTS:
        f = out_dir / f"part_{name}.json"
        if f.exists():
            parts[name] = json.loads(f.read_text())
    summary = {"format": "wheelloader.mpm-verification", "version": 1, "parts": sorted(parts),
               "machine": machine_info(), "git_commit": git_commit(), "results": {}}
    res = summary["results"]
    if "blade" in parts:
        rows = parts["blade"]["result"]["rows"]
        keys = ("soil", "criterion", "depth", "dx", "horizontal", "mckyes_heap_horizontal", "heap_surcharge",
                "ratio", "mckyes_horizontal", "ratio_flat", "ratio_0.25_0.5d", "vertical_over_horizontal",
                "tan_delta", "guard_impulse_share", "wall_s")
        res["blade_vs_mckyes"] = [{k: r.get(k) for k in keys} for r in rows]
        res["blade_within_10_percent"] = all(abs(r["ratio"] - 1.0) <= 0.10 for r in rows if r.get("criterion", True))
    if "wall" in parts:
        rows = parts["wall"]["result"]["rows"]
        res["wall"] = [{k: v for k, v in r.items() if k not in ("displacement", "fx")} for r in rows]
        res["wall_within_15_percent"] = all(abs(r["at_rest_over_reference"] - 1) <= 0.15
                                            and abs(r["passive_over_rankine"] - 1) <= 0.15 for r in rows)
    if "newton" in parts:
        keys = ("horizontal", "vertical_over_horizontal", "mckyes_horizontal", "ratio_flat", "mckyes_heap_horizontal",
                "heap_surcharge", "ratio", "particles", "steps", "wall_s")
        res["newton_blade"] = [{"soil": r["soil"], "depth": r["depth"], "dx": r["dx"],
                                "newton_over_taichi": r["newton_over_taichi"],
                                "newton": {k: r["newton"].get(k) for k in
                                           (*keys, "floor_reaction_over_weight", "slab_width")},
                                "taichi": {k: r["taichi"].get(k) for k in keys}}
                               for r in parts["newton"]["result"]["rows"]]
    if "column" in parts:
        res["column_collapse"] = parts["column"]["result"]["rows"]
    if "cycle" in parts:
        c = parts["cycle"]["result"]
        res["cycle_convergence"] = c["convergence"]
        res["cycle_seed_spread"] = c["seed_spread"]
        res["cycle_mass_balance"] = c["mass_balance"]
        res["cycle_cost"] = {k: {"resolution": r["resolution"], "seed": r["seed"], "particles": r["particles"],
                                 "steps": r["steps"], "wall_s": r["wall_s"]} for k, r in c["runs"].items()}
    summary["part_meta"] = {k: {kk: vv for kk, vv in v.items() if kk != "result"} for k, v in parts.items()}
    (out_dir / "mpm_verification.json").write_text(json.dumps(summary, indent=1))
    figure(parts, out_dir / "mpm_verification.png")
    return summary


def column_runout_lube(a: float) -> float:
    from wheelloader.references.mpm.verification import column_runout_scaling

    return float(column_runout_scaling(a)["lube"])


def column_runout_rods(a: float) -> float:
    from wheelloader.references.mpm.verification import column_runout_true_2d

    return float(column_runout_true_2d(a))


def figure(parts: dict, target: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8.5))
    ax = axes[0, 0]
    if "blade" in parts:
        for r in parts["blade"]["result"]["rows"]:
            if not r.get("criterion", True):
                continue  # the "dirt" rows are in the JSON and the README table, not in this panel
            d = r["depth"]
            line, = ax.plot(np.array(r["travel"]) / d, -np.array(r["fx"]), lw=0.8,
                            label=f"{r['soil']} d={d:g} m ({r['ratio']:.2f}x; "
                                  f"flat {r.get('ratio_flat', r['ratio']):.2f}x)")
            ax.axhline(r["mckyes_horizontal"], color=line.get_color(), ls=":", lw=0.8)
            if "mckyes_heap_horizontal" in r:
                ax.plot([0.5, 1.0], [r["mckyes_heap_horizontal"]] * 2, color=line.get_color(), ls="--", lw=1.5)
    if "newton" in parts:
        for r in parts["newton"]["result"]["rows"]:
            n = r["newton"]
            ax.plot(np.array(n["travel"]) / r["depth"], -np.array(n["fx"]), lw=0.8, ls="-.",
                    label=f"Newton {r['soil']} d={r['depth']:g} m ({n['ratio']:.2f}x; flat {n['ratio_flat']:.2f}x)")
    if "blade" in parts or "newton" in parts:
        ax.axvspan(0.5, 1.0, color="0.9")
        ax.set(xlabel="travel / depth", ylabel="horizontal force [N/m]",
               title="Vertical blade vs McKyes: flat surface (:), with the measured heap as q (--)")
        ax.title.set_fontsize(10)
        ax.legend(fontsize=7, loc="upper left")
    ax = axes[0, 1]
    if "wall" in parts:
        for r in parts["wall"]["result"]["rows"]:
            line, = ax.plot(np.array(r["displacement"]) * 100, -np.array(r["fx"]), lw=0.8, label=r["soil"])
            ax.axhline(r["rankine_passive"], color=line.get_color(), ls="--", lw=0.8)
            ax.axhline(r["at_rest_reference"], color=line.get_color(), ls=":", lw=0.8)
        ax.set(xlabel="wall displacement [cm]", ylabel="wall force [N/m]",
               title="Smooth wall: Rankine passive (--), at rest (:)")
        ax.legend(fontsize=7)
    ax = axes[1, 0]
    if "cycle" in parts:
        c = parts["cycle"]["result"]
        for r in c["runs"].values():
            ax.plot(r["t"], r["F_R_filtered"], lw=1.0, label=f"dx {r['resolution']:g} m, seed {r['seed']}")
        ax.set(xlabel="t [s]", ylabel="F_R filtered (sigma 0.1 s) [N]", title=f"Default cycle ({c['soil']})")
        ax.legend(fontsize=7)
    ax = axes[1, 1]
    if "column" in parts:
        rows = parts["column"]["result"]["rows"]
        for k, dx in enumerate(sorted({r.get("dx", 0.01) for r in rows}, reverse=True)):
            sel = [r for r in rows if r.get("dx", 0.01) == dx]
            ax.plot([r["aspect_ratio"] for r in sel], [r["runout"] for r in sel], "os^"[k % 3], ms=5,
                    label=f"MPM, dx {dx * 100:g} cm ({0.2 / dx:.0f} cells across)")
        aa = np.linspace(0.3, 3.2, 80)
        ax.plot(aa, [column_runout_lube(x) for x in aa], "k--", lw=0.8, label="Lube et al. 2005 (quasi-2-D channel)")
        a2 = aa[aa > 0.65]
        ax.plot(a2, [column_runout_rods(x) for x in a2], "k:", lw=0.8, label="true 2-D rods (arXiv:1512.05180)")
        ax.set(xlabel="aspect ratio a = H0/L0", ylabel="(L_inf - L0) / L0", title="Column collapse run-out")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(target, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--parts", nargs="*", default=[], choices=PARTS, help="parts to run (none: only --report)")
    parser.add_argument("--report", action="store_true", help="assemble the JSON and PNG from the parts present")
    parser.add_argument("--threads", type=int, default=1, help="Taichi CPU threads")
    parser.add_argument("--soil", default="gravel", help="soil preset of the cycle part")
    parser.add_argument("--newton-depths", type=float, nargs="+", default=list(NEWTON_DEPTHS),
                        help="blade depths [m] of the newton part")
    parser.add_argument("--progress", default=None, help="append progress lines to this file")
    parser.add_argument("--reuse", default=None,
                        help="reference-set directory whose SOIL_path1 stands for the default-resolution seed-0 cycle")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    funcs = {"blade": part_blade, "wall": part_wall, "column": part_column, "cycle": part_cycle,
             "newton": part_newton}
    for name in args.parts:
        t0 = time.perf_counter()
        info = {"machine_start": machine_info(), "git_commit": git_commit(), "command": " ".join(sys.argv)}
        result = funcs[name](args)
        info.update(result=result, wall_s=time.perf_counter() - t0, machine_end=machine_info())
        (out / f"part_{name}.json").write_text(json.dumps(info, indent=1))
    if args.report or args.parts:
        summary = report(out)
        print(json.dumps(summary["results"], indent=1)[:4000])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
