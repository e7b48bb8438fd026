"""The plant's own energy-vs-kept frontier over the fixed path's family: can any path reach 0.85x its energy?

#33 asks for paths that spend <= 0.85 x the fixed Bezier path's energy per m^3 (the load lifted to the fixed
path's end height, 1.20 m) and keep at least its fill, paired on the same piles. This benchmark measures, in
the plant itself, what the fixed path's family can reach: on a pile (the loop's fresh cycle-1 pile of a soil, or
a carved start pile read from a saved loop) it digs a seeded design of variants of the fixed path
(:func:`wheelloader.estimator.paths.bezier_path`: the lowest control point's position, the end point, the curl's
onset and end angle, the entry blade angle and the duration; scrambled Sobol, :data:`BOUNDS`), the fixed path
itself, and reads back the loop's planned paths dug on the same pile as reference points (``--references``).
Every variant is placed on the pile as the loop places the fixed path (:func:`wheelloader.planner.bezier_on_face`'s
shift) and slowed down, where needed, to the loader's speed, acceleration and tilt-rate limits
(:func:`within_limits`); a dig whose force went above the loader's push or lift limits is marked and left out of
the frontier.

Per dig: the plant's work along the path plus the lift of its kept load from the path's end to 1.20 m
(:func:`wheelloader.references.metrics.lifted_work`), over the kept fill (the plant's soil inside the bucket at
the end of the path). Per pile: the Pareto frontier (least energy per m^3 for a kept fill), the best ratio to the
fixed path among digs keeping at least its fill, a PNG and a Markdown table.

One process digs the variants one after another (resumable: every dug cycle is saved xz-compressed under
``--cycles-dir`` and read back when its path is the same); a larger ``--count`` keeps the smaller design as its
prefix. Progress goes to ``OUT/progress.txt``, and the JSON is rewritten after every dig.

Usage::

    nice -n 10 python benchmarks/plant_frontier.py --count 8 --taichi-threads 1 \\
        --references data/results/loop_mpm_learned/cycles "learned loop" \\
        --out docs/results/plant_frontier --cycles-dir data/results/plant_frontier/cycles
    python benchmarks/plant_frontier.py --report --out docs/results/plant_frontier     # table and PNG only
    python benchmarks/plant_frontier.py --plant fee-env --count 3 --out /tmp/frontier  # smoke run (FEE env)
"""

from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.provenance import commit_label, load_label, machine_info

#: The fixed Bezier path's parameters (:func:`wheelloader.estimator.paths.default_path`, path 1 of the paper's
#: Fig. 8): tip start, control and end points [m], curl onset (share of the path), blade angles [deg], duration [s].
FIXED: dict[str, float] = {"control_x": 1.20, "control_z": 0.05, "end_x": 1.45, "end_z": 1.20, "curl_from": 0.60,
                           "angle_end_deg": 45.0, "angle_start_deg": -5.0, "duration_s": 4.67}
START = (-0.10, 0.03)
#: The design's box around :data:`FIXED` (low, high): the order is the Sobol dimensions' order.
BOUNDS: dict[str, tuple[float, float]] = {
    "control_x": (0.90, 1.50),       # where the path bottoms out along the face
    "control_z": (-0.10, 0.25),      # how deep the lowest control point lies (the fixed path's: 0.05 m)
    "end_x": (1.25, 1.70),
    "end_z": (0.95, 1.35),           # the end height (the load is lifted from it to 1.20 m either way)
    "curl_from": (0.35, 0.85),       # the curl's onset
    "angle_end_deg": (35.0, 60.0),   # how far the bucket curls
    "angle_start_deg": (-15.0, 10.0),  # the entry blade angle
    "duration_s": (3.5, 6.0),        # the speed
}
DESIGN_SEED = 33
#: The local design's box: :data:`BOUNDS` shrunk by this factor around :data:`FIXED` (``--local``).
LOCAL_SCALE = 0.35
PILE_CHOICES = ("gravel", "sand")


def design(count: int, seed: int = DESIGN_SEED, scale: float = 1.0) -> list[dict[str, float]]:
    """The first ``count`` points of the scrambled Sobol design over :data:`BOUNDS` (a larger count keeps the
    smaller design as its prefix); ``scale`` < 1: the box shrunk by that factor around :data:`FIXED` (the
    same unit points)."""
    from scipy.stats import qmc

    if count <= 0:
        return []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # balance properties need a power of 2; a prefix is wanted
        unit = qmc.Sobol(len(BOUNDS), scramble=True, seed=seed).random(count)
    centre = np.array([FIXED[k] for k in BOUNDS])
    lows = centre + scale * (np.array([b[0] for b in BOUNDS.values()]) - centre)
    highs = centre + scale * (np.array([b[1] for b in BOUNDS.values()]) - centre)
    points = lows + unit * (highs - lows)
    return [{k: float(round(v, 4)) for k, v in zip(BOUNDS, p, strict=True)} for p in points]


#: The planned path's family (``--planned``): its depth below the start pile scaled, its blade angle offset before
#: the final curl, its x stretched about its start (low, high); the base is the first ``--references`` loop's ours.
PLANNED_BOUNDS: dict[str, tuple[float, float]] = {
    "depth_scale": (0.80, 1.25),
    "angle_offset_deg": (-8.0, 8.0),
    "x_stretch": (0.92, 1.08),
}


def planned_design(count: int, seed: int = DESIGN_SEED) -> list[dict[str, float]]:
    """The first ``count`` points of the scrambled Sobol design over :data:`PLANNED_BOUNDS`."""
    from scipy.stats import qmc

    if count <= 0:
        return []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        unit = qmc.Sobol(len(PLANNED_BOUNDS), scramble=True, seed=seed).random(count)
    lows = np.array([b[0] for b in PLANNED_BOUNDS.values()])
    highs = np.array([b[1] for b in PLANNED_BOUNDS.values()])
    return [{k: float(round(v, 4)) for k, v in zip(PLANNED_BOUNDS, p, strict=True)}
            for p in lows + unit * (highs - lows)]


def planned_variant(base: Any, pile: Any, params: dict[str, float], name: str = "planned") -> tuple[Any, float]:
    """The planned path ``base`` with its x stretched about its start, its depth below ``pile``'s surface scaled
    (where it is below) and its blade angle offset (fading out over the last quarter, so the end angle stays);
    slowed down where it would exceed the loader's limits (or the base's own peak, where that is above them).
    ``(path, duration [s])``."""
    from wheelloader.estimator import BucketPath

    x = base.x[0] + params["x_stretch"] * (base.x - base.x[0])
    surface = np.asarray(pile.surface_height(x))
    depth = np.asarray(pile.surface_height(base.x)) - base.z  # the base's depth, carried to the stretched x
    z = np.where(depth > 0.0, surface - params["depth_scale"] * depth, surface - depth)
    u = (base.t - base.t[0]) / (base.t[-1] - base.t[0])
    fade = 1.0 - np.clip((u - 0.75) / 0.25, 0.0, 1.0)
    angle = base.blade_angle + math.radians(params["angle_offset_deg"]) * fade
    t = base.t - base.t[0]
    path = BucketPath(t, x, z, angle, name)
    # the limits, or the base's own peaks where it exceeds them (a planned path's knots make the finite-difference
    # acceleration spike; the planner bounds it at its knots)
    r, cap = limit_ratios(path), {k: max(1.0, v) for k, v in limit_ratios(base).items()}
    scale = max(1.0, r["speed"] / cap["speed"], r["tilt_rate"] / cap["tilt_rate"],
                math.sqrt(r["acceleration"] / cap["acceleration"]))
    if scale > 1.0:
        path = BucketPath(t * scale * 1.01, x, z, angle, name)
    return path, float(path.t[-1])


def limit_ratios(path: Any) -> dict[str, float]:
    """The path's peak tip speed, acceleration and tilt rate over the loader's limits
    (:class:`wheelloader.estimator.Loader`)."""
    from wheelloader.estimator import Loader

    loader = Loader()
    vx, vz, w = path.velocity()
    speed = np.hypot(vx, vz)
    acc = np.hypot(np.gradient(vx, path.t), np.gradient(vz, path.t))
    return {"speed": float(np.max(speed)) / loader.max_speed,
            "tilt_rate": float(np.max(np.abs(w))) / loader.max_tilt_rate,
            "acceleration": float(np.max(acc[2:-2])) / loader.max_acceleration}


def variant_path(params: dict[str, float], rate: float = 60.0, name: str = "variant") -> tuple[Any, float]:
    """The Bezier path of ``params`` on the fresh pile (tip from :data:`START`), lengthened in time where it
    would exceed the loader's speed, acceleration or tilt-rate limits; ``(path, duration used [s])``."""
    from wheelloader.estimator.paths import bezier_path

    def make(duration: float) -> Any:
        return bezier_path(START, (params["control_x"], params["control_z"]), (params["end_x"], params["end_z"]),
                           duration=duration, rate=rate, angle_start=math.radians(params["angle_start_deg"]),
                           angle_end=math.radians(params["angle_end_deg"]), curl_from=params["curl_from"], name=name)

    duration = params["duration_s"]
    path = make(duration)
    r = limit_ratios(path)
    scale = max(1.0, r["speed"], r["tilt_rate"], math.sqrt(r["acceleration"]))
    if scale > 1.0:
        duration = math.ceil(duration * scale * 1.01 * 100) / 100
        path = make(duration)
    return path, duration


def pareto(points: list[tuple[float, float]]) -> list[int]:
    """Indices of the points (energy per m^3, kept fill) that no other point dominates (no more energy and
    no less fill, one of them strictly), by increasing fill."""
    front = []
    for i, (e, f) in enumerate(points):
        dominated = any((e2 <= e and f2 >= f) and (e2 < e or f2 > f) for j, (e2, f2) in enumerate(points) if j != i)
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: points[i][1])


def measure(log: Any, soil: str, z_ref: float) -> dict[str, Any]:
    """A dug cycle's figures: the plant's work, kept fill, the energy with the lift to ``z_ref``, peaks."""
    from wheelloader.references.metrics import above_loader_limits, cycle_work, lifted_work

    energy = cycle_work(log)
    fill = float(log.fill_volume[-1])
    lifted = lifted_work(energy, fill, log, z_ref, soil)
    p = log.path
    depth = np.asarray(log.pile.surface_height(p.x)) - p.z
    return {"energy_J": energy, "fill_m3": fill, "kept_fill": fill / log.bucket.capacity, "lifted_J": lifted,
            "lifted_per_m3_kJ": lifted / fill / 1e3 if fill > 0 else math.inf,
            "energy_per_m3_kJ": energy / fill / 1e3 if fill > 0 else math.inf,
            "peak_F_T_N": float(np.max(log.tangential)), "peak_F_N_N": float(np.max(log.normal)),
            "above_limits": above_loader_limits(log), "max_depth_m": float(np.max(depth)),
            "z_end_m": float(p.z[-1]), "duration_s": float(p.t[-1])}


def pile_for(spec: str) -> tuple[str, Any, str]:
    """``SOIL`` (the loop's fresh pile) or ``SOIL:CYCLES_DIR:K`` (the start pile of cycle K of ours' seed-0 loop
    saved under CYCLES_DIR/loops): ``(soil, pile, label)``."""
    from wheelloader.estimator import Pile
    from wheelloader.saved_loops import load_saved_cycle

    soil, _, rest = spec.partition(":")
    if soil not in PILE_CHOICES:
        raise ValueError(f"--piles {spec}: the soil must be one of {PILE_CHOICES}")
    if not rest:
        return soil, Pile.trapezoid(), soil
    folder, _, k = rest.rpartition(":")
    if not k.isdigit():
        raise ValueError(f"--piles {spec}: expected SOIL:CYCLES_DIR:K")
    log = load_saved_cycle(Path(folder) / "loops" / soil / "seed0" / "ours", int(k), check=False)
    if log is None:
        raise ValueError(f"--piles {spec}: no saved cycle {k} of ours under {folder}/loops")
    return soil, log.pile, f"{soil} ours' cycle-{k} pile"


def references(spec: str, label: str, refs: list[tuple[str, str]], z_ref: float) -> list[dict[str, Any]]:
    """The loops' own cycles on this pile, read back: ours' (and the fixed path's) cycle 1 of seed 0 for a fresh
    pile; for ``SOIL:DIR:K``, ours' cycle K and the fixed path dug on its pile (``paired/.../fixed_on_ours``) of the
    loop DIR only (another loop's cycle K started from another pile)."""
    from wheelloader.saved_loops import load_saved_cycle

    soil, _, rest = spec.partition(":")
    out = []
    for name, folder in refs:
        root = Path(folder)
        if rest:
            pile_folder, _, k_text = rest.rpartition(":")
            if root.resolve() != Path(pile_folder).resolve():
                continue  # another loop's cycle K started from another pile
            k = int(k_text)
            found = [(f"ours ({name})", root / "loops" / soil / "seed0" / "ours", k),
                     (f"fixed ({name}, saved)", root / "paired" / soil / "seed0" / "fixed_on_ours" / f"cycle{k}", 1)]
        else:
            found = [(f"ours ({name})", root / "loops" / soil / "seed0" / "ours", 1),
                     (f"fixed ({name}, saved)", root / "loops" / soil / "seed0" / "fixed", 1)]
        for who, where, k in found:
            log = load_saved_cycle(where, k, check=False)
            if log is not None:
                out.append({"pile": label, "kind": "reference", "name": who, "source": str(where / f"cycle{k}"),
                            **measure(log, soil, z_ref), **shape(log.path)})
    return out


def shape(path: Any) -> dict[str, float]:
    """Where a path goes: its lowest tip height, its end point and its blade angles."""
    i = int(np.argmin(path.z))
    return {"tip_min_z_m": float(path.z[i]), "end_x_m": float(path.x[-1]),
            "angle_start_deg_actual": math.degrees(float(path.blade_angle[0])),
            "angle_end_deg_actual": math.degrees(float(path.blade_angle[-1]))}


def dig_or_read(plant: Any, path: Any, pile: Any, soil: str, seed: int, csv: Path) -> tuple[Any, bool]:
    """The saved cycle at ``csv`` when it was dug along ``path`` (a saved one dug along another path is dug again
    and replaced), else dig it and save it (xz)."""
    from wheelloader.estimator import CycleLog
    from wheelloader.saved_loops import path_digest

    digest = path_digest(path)
    if csv.exists():
        log = CycleLog.load(csv, check=False)
        # a plant that ends the cycle early (the FEE env) logs only the path it ran: the planned path's digest
        if digest in (log.metadata.get("planned_path_digest"), path_digest(log.path)):
            return log, True
    log = plant.dig(path, pile, soil, seed=seed)
    log.metadata["planned_path_digest"] = digest
    csv.parent.mkdir(parents=True, exist_ok=True)
    log.save(csv, overwrite=True)
    return log, False


#: The families a row belongs to: the fixed path's Bezier family (the fixed path, the wide and the local design),
#: the loop's planned path varied (``--planned``) and the loops' own plans (the references).
FAMILIES: dict[str, Callable[[dict[str, Any]], bool]] = {
    "Bézier (the fixed path's)": lambda r: r["kind"] == "variant" and not r["name"].startswith("p"),
    "the planned path varied": lambda r: r["kind"] == "variant" and r["name"].startswith("p"),
    "the loops' own plans": lambda r: r["kind"] == "reference" and r["name"].startswith("ours"),
}


def frontier_at(rows: list[dict[str, Any]], fill: float) -> float:
    """The Pareto frontier of ``rows`` read at kept ``fill`` [m^3], linearly between its neighbours (energy per
    m^3 lifted [kJ/m^3]); NaN outside the frontier's fills."""
    front = [rows[i] for i in pareto([(r["lifted_per_m3_kJ"], r["fill_m3"]) for r in rows])]
    fills = [r["fill_m3"] for r in front]
    if not front or not fills[0] <= fill <= fills[-1]:
        return math.nan
    return float(np.interp(fill, fills, [r["lifted_per_m3_kJ"] for r in front]))


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Per pile: the fixed path's figures, every dig's ratio, the Pareto frontier and the best ratio among digs
    keeping at least the fixed path's fill (within the loader's limits)."""
    out: dict[str, Any] = {}
    for pile in dict.fromkeys(r["pile"] for r in rows):
        sel = [r for r in rows if r["pile"] == pile]
        fixed = next((r for r in sel if r["name"] == "fixed"), None)
        if fixed is None:
            continue
        feasible = [r for r in sel if not r["above_limits"] and math.isfinite(r["lifted_per_m3_kJ"])]
        front = pareto([(r["lifted_per_m3_kJ"], r["fill_m3"]) for r in feasible])
        keep = [r for r in feasible if r["fill_m3"] >= fixed["fill_m3"] and r["name"] != "fixed"]
        best = min(keep, key=lambda r: r["lifted_per_m3_kJ"], default=None)
        dug = [r for r in sel if r["kind"] == "variant"]
        # the frontier of the digs (no reference) read at the fixed path's kept fill: what they spend at that fill
        at_fixed = frontier_at([r for r in feasible if r["kind"] == "variant"], fixed["fill_m3"])
        families = {}
        for family, member in FAMILIES.items():
            mine = [r for r in feasible if member(r)]
            if not mine:
                continue
            kept = [r for r in mine if r["fill_m3"] >= fixed["fill_m3"] and r["name"] != "fixed"]
            top = min(kept, key=lambda r: r["lifted_per_m3_kJ"], default=None)
            families[family] = {
                "count": sum(1 for r in sel if member(r)), "above_limits": sum(1 for r in sel if member(r)
                                                                               and r["above_limits"]),
                "kept_ge_fixed": len(kept),
                "best_ratio": None if top is None else top["lifted_per_m3_kJ"] / fixed["lifted_per_m3_kJ"],
                "best_name": None if top is None else top["name"],
                "best_kept_fill": None if top is None else top["kept_fill"],
                "reach_085": sum(1 for r in kept if r["lifted_per_m3_kJ"] <= 0.85 * fixed["lifted_per_m3_kJ"]),
                "frontier_ratio_at_fixed_fill": frontier_at(mine, fixed["fill_m3"]) / fixed["lifted_per_m3_kJ"]}
        out[pile] = {"fixed_lifted_per_m3_kJ": fixed["lifted_per_m3_kJ"], "fixed_kept_fill": fixed["kept_fill"],
                     "variants": len(dug), "above_limits": sum(r["above_limits"] for r in dug),
                     "frontier": [feasible[i]["name"] for i in front],
                     "kept_ge_fixed": len(keep),
                     "best_ratio_kept_ge_fixed": None if best is None else
                     best["lifted_per_m3_kJ"] / fixed["lifted_per_m3_kJ"],
                     "best_name": None if best is None else best["name"],
                     "reach_085": sum(1 for r in keep if r["lifted_per_m3_kJ"] <= 0.85 * fixed["lifted_per_m3_kJ"]),
                     "family_frontier_ratio_at_fixed_fill": at_fixed / fixed["lifted_per_m3_kJ"],
                     "families": families,
                     "least_ratio_any_fill": min((r["lifted_per_m3_kJ"] for r in feasible if r["name"] != "fixed"),
                                                 default=math.nan) / fixed["lifted_per_m3_kJ"]}
    return out


def markdown(result: dict[str, Any]) -> str:
    """Per pile and family: the best ratio to the fixed path with at least its kept fill, the frontier there."""
    lines = ["| pile | fixed path: energy per m³ lifted / kept fill | family | digs (above the loader's limits) | "
             "best ratio with kept ≥ fixed (dig, kept fill) | digs with kept ≥ fixed / of them ≤ 0.85× | the "
             "family's frontier at the fixed path's kept fill |", "|---|---|---|---|---|---|---|"]
    for pile, s in result["summary"].items():
        fixed = f"{s['fixed_lifted_per_m3_kJ']:.1f} kJ/m³ / {s['fixed_kept_fill']:.1%}"
        for family, f in s.get("families", {}).items():
            best = ("–" if f["best_ratio"] is None
                    else f"**{f['best_ratio']:.3f}** ({f['best_name']}, {f['best_kept_fill']:.1%})")
            ratio = f["frontier_ratio_at_fixed_fill"]
            front = "–" if math.isnan(ratio) else f"{ratio:.3f}×"
            lines.append(f"| {pile} | {fixed} | {family} | {f['count']} ({f['above_limits']}) | {best} | "
                         f"{f['kept_ge_fixed']} / {f['reach_085']} | {front} |")
    return "\n".join(lines + footer(result)) + "\n"


def digs_markdown(result: dict[str, Any]) -> str:
    """Every dig and reference by pile, by increasing energy per m^3."""
    lines: list[str] = []
    lines += ["| pile | dig | energy per m³ lifted | ratio to fixed | kept fill | end height | plant's energy "
              "per m³ | peak F_T / F_N | on the frontier | control point (x, z) | end (x, z) | curl from / end angle "
              "| entry angle | duration |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for pile, s in result["summary"].items():
        sel = sorted((r for r in result["rows"] if r["pile"] == pile), key=lambda r: r["lifted_per_m3_kJ"])
        base = s["fixed_lifted_per_m3_kJ"]
        for r in sel:
            p = r.get("params")
            if p and "depth_scale" in p:
                geo = (f"the first reference's planned path, depth × {p['depth_scale']:.2f}, blade "
                       f"{p['angle_offset_deg']:+.0f}°, x × {p['x_stretch']:.2f} | – | – | – | ")
            elif p:
                geo = (f"({p['control_x']:.2f}, {p['control_z']:.2f}) m | ({p['end_x']:.2f}, {p['end_z']:.2f}) m | "
                       f"{p['curl_from']:.2f} / {p['angle_end_deg']:.0f}° | {p['angle_start_deg']:.0f}° | ")
            else:
                geo = "the loop's saved cycle | – | – | – | "
            geo += f"{r['duration_s']:.2f} s"
            mark = " ⚠ above limits" if r["above_limits"] else ""
            lines.append(f"| {pile} | {r['name']}{mark} | {r['lifted_per_m3_kJ']:.1f} kJ/m³ | "
                         f"{r['lifted_per_m3_kJ'] / base:.3f} | {r['kept_fill']:.1%} | {r['z_end_m']:.2f} m | "
                         f"{r['energy_per_m3_kJ']:.1f} kJ/m³ | {r['peak_F_T_N'] / 1e3:.1f} / "
                         f"{r['peak_F_N_N'] / 1e3:.1f} kN | {'yes' if r['name'] in s['frontier'] else ''} | {geo} |")
    return "\n".join(lines + footer(result)) + "\n"


def footer(result: dict[str, Any]) -> list[str]:
    """The commands that made the result, their commit and load, and what the figures are."""
    lines = [""]
    for run in result.get("invocations") or [result]:
        st = run["settings"]
        local = (f" --local {st['local']}" if st.get("local") else "") + (
            f" --planned {st['planned']}" if st.get("planned") else "")
        lines.append(f"*`python benchmarks/plant_frontier.py --count {st['count']}{local} --piles "
                     f"{' '.join(st['piles'])}` ({st['plant']} plant, dx {st['resolution']} m, seed {st['seed']}, "
                     f"design seed {st['design_seed']}) at {commit_label(run['machine'])}; "
                     + (f"{run['dug']} digs (the others read back) in " if "dug" in run else "")
                     + f"{run['dig_s'] / 60:.0f} min, load average at the end "
                     f"{load_label(run['machine'])}.*")
    lines += ["", f"*Energy per m³ lifted: the plant's work along the "
              f"path plus the lift of the kept load from the path's end to {result['z_ref_m']:.2f} m, over the kept "
              "fill (soil inside the bucket at the path's end, % of the nominal 0.2 m³). References: the loops' own "
              "cycles on the same pile, read back.*"]
    return lines


def figure(result: dict[str, Any], target: Path) -> None:
    """Energy per m^3 lifted vs kept fill per pile: the digs, the frontier, the fixed path, the 0.85x line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    piles = list(result["summary"])
    fig, axes = plt.subplots(1, max(1, len(piles)), figsize=(5.5 * max(1, len(piles)), 4.5), squeeze=False)
    for ax, pile in zip(axes[0], piles, strict=False):
        s = result["summary"][pile]
        sel = [r for r in result["rows"] if r["pile"] == pile]
        var = [r for r in sel if r["kind"] == "variant" and r["name"] != "fixed"]
        ok = [r for r in var if not r["above_limits"]]
        bad = [r for r in var if r["above_limits"]]
        ax.scatter([100 * r["kept_fill"] for r in ok], [r["lifted_per_m3_kJ"] for r in ok], s=18, c="tab:blue",
                   label="variants")
        if bad:
            ax.scatter([100 * r["kept_fill"] for r in bad], [r["lifted_per_m3_kJ"] for r in bad], s=18,
                       marker="x", c="tab:gray", label="above the loader's limits")
        front = [next(r for r in sel if r["name"] == n) for n in s["frontier"]]
        ax.plot([100 * r["kept_fill"] for r in front], [r["lifted_per_m3_kJ"] for r in front], "-", c="tab:blue",
                lw=1, label="Pareto frontier")
        for r in (r for r in sel if r["kind"] == "reference" and not r["name"].startswith("fixed")):
            ax.scatter([100 * r["kept_fill"]], [r["lifted_per_m3_kJ"]], marker="^", s=40, label=r["name"])
        ax.scatter([100 * s["fixed_kept_fill"]], [s["fixed_lifted_per_m3_kJ"]], marker="*", s=150, c="tab:red",
                   label="fixed path", zorder=5)
        ax.axhline(0.85 * s["fixed_lifted_per_m3_kJ"], c="tab:red", ls="--", lw=1, label="0.85 × fixed")
        ax.axvline(100 * s["fixed_kept_fill"], c="tab:red", ls=":", lw=1)
        top = 2.0 * s["fixed_lifted_per_m3_kJ"]
        off = sum(1 for r in sel if r["lifted_per_m3_kJ"] > top)
        ax.set_ylim(0.5 * s["fixed_lifted_per_m3_kJ"], top)
        ax.set_title(pile + (f" ({off} dig{'s' if off > 1 else ''} above 2 × fixed, off the scale)" if off else ""),
                     fontsize=9)
        ax.set_xlabel("kept fill, % of the nominal bucket")
        ax.set_ylabel(f"energy per m³, lifted to {result['z_ref_m']:.2f} m [kJ/m³]")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(target, dpi=110)
    plt.close(fig)


def _read(source: str) -> Any:
    """The saved cycle ``source`` (a folder and a stem)."""
    from wheelloader.estimator import CycleLog
    from wheelloader.estimator.cyclelog import find_cycle_log

    where = Path(source)
    found = find_cycle_log(where.parent, where.name)
    if found is None:
        raise SystemExit(f"wheelloader: error: {source}: no saved cycle")
    return CycleLog.load(found, check=False)


def path_figure(result: dict[str, Any], target: Path) -> None:
    """Per pile, what the paths look like: the tip of the fixed path, of the loops' planned paths, of the
    cheapest dig keeping at least the fixed path's fill and of the cheapest dig at any fill, over the start pile's
    surface (read from the saved cycles named by the rows' ``source``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wheelloader.estimator import CycleLog
    from wheelloader.estimator.cyclelog import find_cycle_log

    def load(row: dict[str, Any]) -> Any:
        where = Path(row["source"])
        found = find_cycle_log(where.parent, where.name)
        return None if found is None else CycleLog.load(found, check=False)

    piles = list(result["summary"])
    fig, axes = plt.subplots(1, max(1, len(piles)), figsize=(5.5 * max(1, len(piles)), 4.0), squeeze=False)
    for ax, pile in zip(axes[0], piles, strict=False):
        s = result["summary"][pile]
        sel = {r["name"]: r for r in result["rows"] if r["pile"] == pile and "source" in r}
        shown = [("fixed", "fixed path", "tab:red")]
        shown += [(n, n, c) for n, c in zip((n for n in sel if n.startswith("ours")), ("tab:blue", "tab:green"),
                                            strict=False)]
        if s["best_name"] and s["best_name"] in sel and not s["best_name"].startswith("ours"):
            shown.append((s["best_name"], f"{s['best_name']}: least energy with kept ≥ fixed", "tab:purple"))
        variants = [r for r in sel.values() if r["kind"] == "variant" and not r["above_limits"]]
        cheapest = min(variants, key=lambda r: r["lifted_per_m3_kJ"], default=None)
        if cheapest is not None and cheapest["name"] not in {n for n, _, _ in shown}:
            shown.append((cheapest["name"], f"{cheapest['name']}: least energy at any fill", "tab:gray"))
        surface_drawn = False
        for name, label, colour in shown:
            log = load(sel[name]) if name in sel else None
            if log is None:
                continue
            if not surface_drawn:
                ax.fill_between(log.pile.x, log.pile.heights, color="tan", alpha=0.5, lw=0, label="start pile")
                surface_drawn = True
            r = sel[name]
            ax.plot(log.path.x, log.path.z, c=colour, lw=1.5,
                    label=f"{label} ({r['lifted_per_m3_kJ']:.1f} kJ/m³, kept {r['kept_fill']:.0%})")
        ax.set_xlim(-0.3, 2.0)
        ax.set_ylim(-0.1, 1.45)
        ax.set_aspect("equal")
        ax.set_title(f"{pile}: bucket tip paths", fontsize=9)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.legend(fontsize=6, loc="upper left")
    fig.tight_layout()
    fig.savefig(target, dpi=110)
    plt.close(fig)


def write(result: dict[str, Any], out: Path) -> None:
    result["summary"] = summarise(result["rows"])
    tmp = out / "plant_frontier.json.tmp"  # whole or not at all: a run stopped while writing keeps the old JSON
    tmp.write_text(json.dumps(result, indent=1, default=str))
    tmp.replace(out / "plant_frontier.json")
    (out / "plant_frontier.md").write_text(markdown(result))
    (out / "plant_frontier_digs.md").write_text(digs_markdown(result))
    figure(result, out / "plant_frontier.png")
    path_figure(result, out / "plant_frontier_paths.png")


def placement(pile: Any) -> float:
    """The shift along x [m] by which the loop places the fixed path on ``pile``
    (:func:`wheelloader.planner.bezier_on_face`; the very float of its search grid, so that the fixed path placed
    here is the loop's bit for bit)."""
    from wheelloader.planner import bezier_on_face

    offset = float(bezier_on_face(pile).x[0] - START[0])
    grid = np.arange(0.0, 3.0 + 1e-9, 0.02)  # bezier_on_face's default search (max_shift 3 m, step 2 cm)
    return float(grid[int(np.argmin(np.abs(grid - offset)))])


def run(args: argparse.Namespace, out: Path, piles: list[tuple[str, Any, str]]) -> dict[str, Any]:
    from wheelloader.planner.kept import dump_height
    from wheelloader.references import make_plant

    if args.plant == "mpm" and args.taichi_threads is not None:
        from wheelloader.references.mpm import taichi_module

        taichi_module(args.taichi_threads)
    plant = (make_plant("mpm", resolution=args.resolution, threads=args.threads) if args.plant == "mpm"
             else make_plant(args.plant))
    z_ref = dump_height()
    cycles = Path(args.cycles_dir) if args.cycles_dir else out / "cycles"
    progress = out / "progress.txt"
    rows: list[dict[str, Any]] = []
    for spec, (_, _, label) in zip(args.piles, piles, strict=True):
        rows += references(spec, label, args.references or [], z_ref)
    settings = {"count": args.count, "piles": args.piles, "plant": args.plant, "resolution": args.resolution,
                "threads": args.threads, "seed": args.seed, "design_seed": args.design_seed,
                "references": args.references, "local": args.local, "local_scale": LOCAL_SCALE,
                "planned": args.planned}
    # the other piles' rows of an earlier invocation into the same OUT stay (one JSON for every pile)
    saved = out / "plant_frontier.json"
    earlier = json.loads(saved.read_text()) if saved.is_file() else {}
    labels = {label for _, _, label in piles}
    rows = [r for r in earlier.get("rows", []) if r["pile"] not in labels] + rows
    invocations = [i for i in earlier.get("invocations", []) if not labels & set(i.get("labels", []))]
    this = {"settings": settings, "labels": sorted(labels), "machine": machine_info(), "dig_s": 0.0}
    result = {"benchmark": "plant_frontier", "plant": args.plant, "z_ref_m": z_ref, "bounds": BOUNDS, "fixed": FIXED,
              "settings": settings, "invocations": [*invocations, this], "machine": this["machine"], "rows": rows,
              "dig_s": 0.0}
    started = time.perf_counter()
    points = [("fixed", FIXED)] + [(f"v{i + 1:02d}", p) for i, p in enumerate(design(args.count, args.design_seed))]
    points += [(f"l{i + 1:02d}", p) for i, p in enumerate(design(args.local, args.design_seed, LOCAL_SCALE))]
    points += [(f"p{i + 1:02d}", p) for i, p in enumerate(planned_design(args.planned, args.design_seed))]
    bases = {}
    if args.planned:
        for spec, (_, _, label) in zip(args.piles, piles, strict=True):
            ours = [r for r in rows if r["pile"] == label and r["kind"] == "reference" and r["name"].startswith("ours")]
            if not ours:
                raise SystemExit(f"wheelloader: error: --planned: no planned path of a --references loop on {spec}")
            bases[label] = _read(ours[0]["source"]).path
    # interleave the piles: each pile's design grows together, so a run cut short leaves every pile a prefix
    for name, params in points:
        for soil, pile, label in piles:
            shift = placement(pile)
            if name.startswith("p"):
                path, duration = planned_variant(bases[label], pile, params, name=name)
                shift = 0.0
            else:
                path, duration = variant_path(params, name=name)
                path = path.shifted(dx=shift)
            folder = cycles / label.replace(" ", "_").replace("'", "")
            t0 = time.perf_counter()
            log, resumed = dig_or_read(plant, path, pile, soil, args.seed, folder / f"{name}.csv.xz")
            row = {"pile": label, "kind": "variant", "name": name, "params": params, "duration_used_s": duration,
                   "source": str(folder / name),
                   "shift_m": shift, "limit_ratios": limit_ratios(path), "resumed": resumed,
                   **measure(log, soil, z_ref), **shape(path)}
            rows.append(row)
            line = (f"{time.strftime('%H:%M:%S')} {label} {name}: {row['lifted_per_m3_kJ']:.1f} kJ/m3 lifted, kept "
                    f"{row['kept_fill']:.1%}{' (resumed)' if resumed else f', {time.perf_counter() - t0:.0f} s'}"
                    f"{' ABOVE LIMITS' if row['above_limits'] else ''}")
            print(line, flush=True)
            with progress.open("a") as f:
                f.write(line + "\n")
            result["dig_s"] = this["dig_s"] = time.perf_counter() - started
            if not resumed:
                result["machine"] = this["machine"] = machine_info()
                this["dug"] = this.get("dug", 0) + 1
            write(result, out)
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/plant_frontier", help="output directory")
    parser.add_argument("--cycles-dir", default=None, metavar="DIR", help="dug cycles (resume cache; OUT/cycles)")
    parser.add_argument("--count", type=int, default=8, help="design points per pile (besides the fixed path)")
    parser.add_argument("--local", type=int, default=0,
                        help=f"further points (named lNN) of the design in the box shrunk by {LOCAL_SCALE} around "
                             "the fixed path, dug after the others")
    parser.add_argument("--planned", type=int, default=0,
                        help="further points (named pNN): the first --references loop's planned path on the pile with "
                             "its depth, blade angle and length varied (PLANNED_BOUNDS), dug last")
    parser.add_argument("--design-seed", type=int, default=DESIGN_SEED, help="seed of the scrambled Sobol design")
    parser.add_argument("--piles", nargs="+", default=["gravel", "sand"],
                        help="SOIL (the fresh pile) or SOIL:CYCLES_DIR:K (ours' cycle-K start pile of a saved loop)")
    parser.add_argument("--references", nargs=2, action="append", metavar=("CYCLES_DIR", "LABEL"), default=None,
                        help="a saved loop (CYCLES_DIR with loops/ and paired/) whose cycles on these piles are "
                             "read back as reference points (repeatable)")
    parser.add_argument("--plant", choices=("mpm", "fee-env"), default="mpm", help="the plant (fee-env: smoke runs)")
    parser.add_argument("--resolution", type=float, default=0.02, help="MPM grid spacing [m]")
    parser.add_argument("--threads", type=int, default=2, help="MPM lanes (the loop's: 2; the results depend on it)")
    parser.add_argument("--taichi-threads", type=int, default=None, metavar="N", help="CPU threads Taichi runs")
    parser.add_argument("--seed", type=int, default=0, help="plant seed")
    parser.add_argument("--report", action="store_true", help="only regenerate the table and PNG from the JSON")
    args = parser.parse_args(argv)
    if args.count < 0 or args.local < 0 or args.planned < 0:
        parser.exit(2, "wheelloader: error: --count, --local and --planned must be >= 0\n")
    out = Path(args.out)
    if args.report:
        saved = out / "plant_frontier.json"
        if not saved.is_file():
            parser.exit(2, f"wheelloader: error: --report: {saved} not found\n")
        result = json.loads(saved.read_text())
        write(result, out)
    else:
        if args.references:
            args.references = [(label, folder) for folder, label in args.references]
        try:
            piles = [pile_for(spec) for spec in args.piles]
        except ValueError as exc:
            parser.exit(2, f"wheelloader: error: {exc}\n")
        out.mkdir(parents=True, exist_ok=True)
        result = run(args, out, piles)
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
