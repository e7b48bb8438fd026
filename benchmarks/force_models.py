"""Which definition of the ``"fee-payload"`` force model helps: one path calibrated, the others predicted.

For each soil of ``data/mpm`` (four paths each): calibrate on one path (varpro, the model's own carving,
``fill="model"``, the reference Gaussian-filtered at sigma 0.1 s) and predict the other three. Reported per
variant, the median over the 48 predictions of the F_R RMSE (% of the mean |F_R| in soil):

* ``in soil``: the tip below the surface (what the estimator fits and the paper reports);
* ``whole record``: every sample from the tip's first entry on (the carried load after the exit counts);
* ``after exit``: the samples after the entry with the tip above the surface.

Variants:

* ``fee``: the paper's FEE; 0 after the exit.
* ``fee-payload``: the force model of that name (``force_models``): the FEE with the carved fill in soil, the
  payload's kept soil carried as the tip leaves.
* ``kept fill, carried in soil``: the first definition of ``"fee-payload"``: the kept soil as the surcharge's
  fill and its weight on the bucket in and out of soil.
* ``kept fill``: the kept soil as the surcharge's fill, no carried load.

Run: ``python benchmarks/force_models.py --out docs/results/force_models`` (about 30 s; writes
``force_models.json`` and ``table.md``).

``--fit-payload`` instead fits :data:`~wheelloader.estimator.force_models.DEFAULT_PAYLOAD`'s data set: the
payload (:func:`~wheelloader.estimator.payload.fit_payload`) on the MPM cycles of ``data/mpm`` and
``data/results/adaptation_mpm*/cycles`` except the held-out soil (dirt) and pile (25 deg, ``slope25``);
writes ``payload.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wheelloader.estimator import DEFAULT_PAYLOAD, CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.payload import fit_payload, kept_volume
from wheelloader.estimator.validity import ModelOptions
from wheelloader.provenance import machine_info
from wheelloader.references.filtering import filtered

SOILS = ("dirt", "gravel", "sand", "modified_sand")
VARIANTS = ("fee", "fee-payload", "kept fill, carried in soil", "kept fill")


def _kept_log(log: CycleLog) -> CycleLog:
    """The log with the payload's kept soil (of the model's carving) as its logged fill."""
    state = log.contact_state(fill="model")
    kept = kept_volume(state.carve.removed_history, log.bucket.capacity, DEFAULT_PAYLOAD)
    return replace(log, fill_volume=np.asarray(kept, dtype=float), measured_load=None)


def _options(variant: str) -> CalibrationOptions:
    if variant == "fee":
        return CalibrationOptions(fill="model")
    if variant == "fee-payload":
        return CalibrationOptions(force_model="fee-payload")
    return CalibrationOptions(fill="log", model_options=ModelOptions(carried_load=variant.endswith("in soil")))


def _errors(log: CycleLog, f_t: np.ndarray, f_n: np.ndarray) -> dict:
    depth = log.contact_state(fill="model").depth
    inside = depth > 0.0
    obs, pred = np.hypot(log.tangential, log.normal), np.hypot(f_t, f_n)
    scale = float(np.mean(np.abs(obs[inside])))
    whole = np.arange(len(obs)) >= int(np.flatnonzero(inside)[0])
    after = whole & ~inside

    def rmse(m):
        return 100.0 * math.sqrt(float(np.mean((pred[m] - obs[m]) ** 2))) / scale if np.any(m) else None

    return {"in_soil": rmse(inside), "whole_record": rmse(whole), "after_exit": rmse(after)}


def run(data: Path, sigma: float) -> dict:
    rows = []
    for soil in SOILS:
        logs = {i: filtered(CycleLog.load(data / f"{soil}_path{i}.csv"), sigma) for i in range(1, 5)}
        for train in logs:
            for variant in VARIANTS:
                kept = variant.startswith("kept")
                t0 = time.perf_counter()
                cal = calibrate(_kept_log(logs[train]) if kept else logs[train], options=_options(variant))
                seconds = time.perf_counter() - t0
                for test in logs:
                    if test == train:
                        continue
                    pred = predict(cal, _kept_log(logs[test]) if kept else logs[test])
                    rows.append({"soil": soil, "train": f"path{train}", "test": f"path{test}", "variant": variant,
                                 "calibration_s": seconds, **_errors(logs[test], pred.tangential, pred.normal)})
    summary = {}
    for variant in VARIANTS:
        mine = [r for r in rows if r["variant"] == variant]
        med = lambda key, rs=mine: float(np.median([r[key] for r in rs if r[key] is not None]))  # noqa: E731
        summary[variant] = {"in_soil": med("in_soil"), "whole_record": med("whole_record"),
                            "after_exit": med("after_exit"), "calibration_s": med("calibration_s"),
                            "in_soil_per_soil": {s: float(np.median([r["in_soil"] for r in mine if r["soil"] == s]))
                                                 for s in SOILS}}
    return {"benchmark": "force_models", "data": str(data), "sigma_s": sigma, "summary": summary, "rows": rows,
            "machine": machine_info()}


def payload_cycles(data: Path, results: Path) -> list[Path]:
    """The cycles DEFAULT_PAYLOAD is fitted to: data/mpm and the saved MPM loops, without dirt and the 25 deg pile."""
    found = sorted(data.glob("*.csv")) + sorted(results.glob("adaptation_mpm*/cycles/**/*.csv.xz"))
    return [p for p in found if not p.name.startswith("dirt") and "slope25" not in p.name]


def table(result: dict) -> str:
    """The summary as a Markdown table."""
    lines = ["| variant | in soil | whole record | after exit | in soil per soil (dirt, gravel, sand, mod. sand) |",
             "|---|---|---|---|---|"]
    for variant, s in result["summary"].items():
        per = ", ".join(f"{v:.1f}" for v in s["in_soil_per_soil"].values())
        lines.append(f"| {variant} | {s['in_soil']:.1f} % | {s['whole_record']:.1f} % | {s['after_exit']:.1f} % "
                     f"| {per} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/mpm"), help="folder of the MPM cycles")
    parser.add_argument("--sigma", type=float, default=0.1, help="Gaussian filter sigma of the reference [s]")
    parser.add_argument("--results", type=Path, default=Path("data/results"),
                        help="folder of the saved MPM loops (--fit-payload)")
    parser.add_argument("--fit-payload", action="store_true", help="fit the payload instead (payload.json)")
    parser.add_argument("--out", type=Path, required=True, help="output folder (force_models.json, table.md)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.fit_payload:
        paths = payload_cycles(args.data, args.results)
        payload = fit_payload([CycleLog.load(p) for p in paths])
        out = {"cycles": len(paths), "payload": payload.to_dict(), "machine": machine_info()}
        (args.out / "payload.json").write_text(json.dumps(out, indent=1) + "\n")
        print(f"{len(paths)} cycles: {payload}")
        return
    result = run(args.data, args.sigma)
    (args.out / "force_models.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "table.md").write_text(table(result))
    print(table(result), end="")


if __name__ == "__main__":
    main()
