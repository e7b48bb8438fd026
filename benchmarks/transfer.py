"""Does a calibrated model carry over to paths it has not seen? The FEE against the payload model and data priors.

The data are the project's continuum (MPM) cycles, split by case family (soil x pile x path family), never by
sample (the split is written to ``manifest.json``):

* **train**: the saved MPM loops (``data/results/adaptation_mpm*/cycles``: gravel and sand, the loops' carved
  piles, the four strategies' paths). They give the payload (``fit_payload``) and the data priors (below); no
  test cycle is in them.
* **test**: ``data/mpm``'s four smooth paths on the trapezoid pile (a path family no loop digs), per soil:
  gravel and sand (soils seen in training, paths not), modified sand and dirt (soils never seen in training:
  held out), and the 25 deg pile (``gravel_slope25_path1``: a pile never seen in training, predicted from the
  gravel paths on the trapezoid pile).

Variants (calibration on the reference Gaussian-filtered at sigma 0.1 s, the model's own carving):

* ``fee``: the paper's FEE (``fill="model"``);
* ``fee-payload``: ``force_model="fee-payload"`` with the payload fitted to the training cycles;
* ``fee-payload + prior``: the same with a Gaussian prior (the MAP estimate of ``CalibrationOptions(prior=)``) on
  phi, delta and n, whose mean is the median of the per-cycle fits over the training cycles and whose standard
  deviation is their robust spread (1.4826 MAD): what one shallow cycle cannot pin is held near what the
  continuum's other cycles say;
* ``fee-payload + fixed phi, n``: phi and n fixed at those medians (equal bounds), the rest fitted;
* ``fee-payload + input prior``: a Gaussian prior on phi, delta and n whose mean is the median of the training
  soils' own parameters (the plant's inputs, ``soil_params`` in each log's metadata) and whose standard
  deviation is :data:`INPUT_PRIOR_STD`: the physical values, where the fits' medians are not;
* ``fee-payload + residual``: a learned correction beyond the FEE (``wheelloader.estimator.residual``, a ridge
  on dimensionless inputs) trained on the training cycles' residuals after their own ``fee-payload`` fits; the
  soil is fitted to the measured forces minus the residual, and the residual added to the prediction (the band
  shifted with it).

Reported per variant and row (soil or pile): the median F_R RMSE in soil (% of the mean observed |F_R| in soil)
of unseen paths predicted from ONE cycle, from TWO cycles (two neighbouring paths, the other two predicted), the
floor (each path fitted to itself), filtered and unfiltered; the whole-record error (every sample from the first
entry on, the carried load after the exit included); the 90 % band's coverage of the unseen paths' in-soil
samples; the kept fill's relative error at the path's end (the FEE's carved fill, the payload's kept soil,
against the plant's); the median calibration time of one cycle.

Run: ``python benchmarks/transfer.py --out docs/results/transfer`` (a few minutes; writes ``transfer.json``,
``manifest.json``, ``table.md`` and ``transfer.png``).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from wheelloader.estimator import CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.payload import PayloadOptions, fit_payload, kept_fill, payload_contact_state
from wheelloader.estimator.residual import (
    ResidualModel,
    corrected_log,
    features,
    fit_residual,
    force_scale,
    residual_forces,
)
from wheelloader.provenance import machine_info
from wheelloader.references.filtering import filtered

VARIANTS = ("fee", "fee-payload", "fee-payload + prior", "fee-payload + fixed phi, n", "fee-payload + input prior",
            "fee-payload + residual")
#: Standard deviation of the input prior (the training soils' own parameters are known exactly; their spread
#: across soils is what a new soil may differ by): phi and delta 5 deg, n 0.15.
INPUT_PRIOR_STD = {"phi": math.radians(5.0), "delta": math.radians(5.0), "n": 0.15}
PRIOR_NAMES = ("phi", "delta", "n")
ROWS = ("gravel", "sand", "modified_sand (unseen soil)", "dirt (held-out soil)", "25 deg pile (held-out pile)")
SIGMA = 0.1
BAND = 0.9


def split(data: Path, results: Path) -> dict:
    """The train/test split by case family (module docstring)."""
    train = sorted(str(p) for p in results.glob("adaptation_mpm*/cycles/**/*.csv.xz"))
    test = {soil: [str(data / f"{soil}_path{i}.csv") for i in range(1, 5)]
            for soil in ("gravel", "sand", "modified_sand", "dirt")}
    test["gravel_slope25"] = [str(data / "gravel_slope25_path1.csv")]
    return {"rule": "split by case family (soil x pile x path family); train: the saved MPM loops (gravel, sand; "
                    "their carved piles; the loops' strategies); test: data/mpm's four smooth paths on the trapezoid "
                    "pile; held out of training entirely: the soils modified_sand and dirt, the 25 deg pile",
            "train": train, "test": test}


class Pair:
    """A cycle's raw and filtered log."""

    def __init__(self, path: str):
        self.raw = CycleLog.load(path)
        self.filt = filtered(self.raw, SIGMA)
        self.name = Path(path).name


def data_prior(train: list[Pair], payload: PayloadOptions, residual_samples: list | None = None) -> dict:
    """Median and robust spread of phi, delta, n over the training cycles' own fits (fee-payload).

    ``residual_samples`` (a list) receives each cycle's ``(inputs, residual / s)`` after its entry.
    """
    fits = []
    for pair in train:
        try:
            cal = calibrate(pair.filt, options=CalibrationOptions(force_model="fee-payload", payload=payload))
        except Exception as exc:  # a loop cycle the calibration refuses (too few in-soil samples)
            print(f"  prior: {pair.name} skipped ({exc})", flush=True)
            continue
        fits.append([getattr(cal.params, name) for name in PRIOR_NAMES])
        if residual_samples is not None:
            pred = predict(cal, pair.filt)
            after = np.arange(len(pair.filt)) >= int(np.flatnonzero(pred.state.depth > 0.0)[0])
            scale = force_scale(pair.filt)
            res = np.column_stack([pair.filt.tangential - pred.tangential, pair.filt.normal - pred.normal]) / scale
            residual_samples.append((features(pred.state, pair.filt)[after], res[after]))
    arr = np.array(fits)
    med = np.median(arr, axis=0)
    spread = 1.4826 * np.median(np.abs(arr - med), axis=0)
    inputs = np.array([[float(pair.raw.metadata["soil_params"][name]) for name in PRIOR_NAMES] for pair in train
                       if isinstance(pair.raw.metadata.get("soil_params"), dict)])
    return {"cycles": len(fits), "median": dict(zip(PRIOR_NAMES, med.tolist(), strict=True)),
            "spread": dict(zip(PRIOR_NAMES, spread.tolist(), strict=True)),
            "input_median": dict(zip(PRIOR_NAMES, np.median(inputs, axis=0).tolist(), strict=True)),
            "input_cycles": int(inputs.shape[0])}


def options_for(variant: str, payload: PayloadOptions, prior: dict) -> CalibrationOptions:
    if variant == "fee":
        return CalibrationOptions(fill="model")
    if variant in ("fee-payload", "fee-payload + residual"):
        return CalibrationOptions(force_model="fee-payload", payload=payload)
    med, spread = prior["median"], prior["spread"]
    if variant == "fee-payload + input prior":
        ranges = {name: (prior["input_median"][name] - math.sqrt(3.0) * INPUT_PRIOR_STD[name],
                         prior["input_median"][name] + math.sqrt(3.0) * INPUT_PRIOR_STD[name]) for name in PRIOR_NAMES}
        return CalibrationOptions(force_model="fee-payload", payload=payload, prior=ranges)
    if variant == "fee-payload + prior":
        # CalibrationOptions(prior=) takes ranges: mean mid-range, std range / sqrt(12)
        ranges = {name: (med[name] - math.sqrt(3.0) * max(spread[name], 1e-6),
                         med[name] + math.sqrt(3.0) * max(spread[name], 1e-6)) for name in PRIOR_NAMES}
        return CalibrationOptions(force_model="fee-payload", payload=payload, prior=ranges)
    bounds = {"phi": (med["phi"], med["phi"]), "n": (med["n"], med["n"])}
    return CalibrationOptions(force_model="fee-payload", payload=payload, bounds=bounds)


def errors(pred, pair: Pair, residual: ResidualModel | None = None) -> dict:
    """In-soil F_R RMSE (filtered, unfiltered), the whole record's, and the band's coverage (filtered)."""
    inside = pred.state.depth > 0.0
    pr = np.hypot(pred.tangential, pred.normal)
    shift = 0.0
    if residual is not None:
        r_t, r_n = residual_forces(residual, pred.state, pair.filt)
        corrected = np.hypot(pred.tangential + r_t, pred.normal + r_n)
        shift, pr = corrected - pr, corrected
    out = {}
    for key, log in (("filtered", pair.filt), ("unfiltered", pair.raw)):
        obs = np.hypot(log.tangential, log.normal)
        scale = float(np.mean(obs[inside]))
        out[key] = 100.0 * math.sqrt(float(np.mean((pr[inside] - obs[inside]) ** 2))) / scale
        if key == "filtered":
            whole = np.arange(len(obs)) >= int(np.flatnonzero(inside)[0])
            out["whole_record"] = 100.0 * math.sqrt(float(np.mean((pr[whole] - obs[whole]) ** 2))) / scale
            if pred.band is not None:
                out["band_coverage"] = 100.0 * pred.band.coverage(obs - shift, inside)
    return out


def kept_fill_error(variant: str, pred, pair: Pair, payload: PayloadOptions) -> float | None:
    """Relative error [%] of the predicted kept fill at the path's end against the plant's logged fill."""
    if pair.raw.fill_volume is None or pair.raw.fill_volume[-1] <= 0.0:
        return None
    cap = pair.raw.bucket.capacity
    model = float(pred.state.fill_volume[-1]) if variant == "fee" else kept_fill(pred.state, cap, payload)
    return 100.0 * abs(model - float(pair.raw.fill_volume[-1])) / float(pair.raw.fill_volume[-1])


def evaluate(variant: str, options: CalibrationOptions, test: dict[str, list[Pair]], payload: PayloadOptions,
             residual: ResidualModel | None = None) -> dict:
    records = []
    seconds = []

    def fitted(pair: Pair):
        if residual is None:
            return pair.filt
        return corrected_log(residual, payload_contact_state(pair.filt, payload), pair.filt)

    def cal_of(pairs: list[Pair]):
        t0 = time.perf_counter()
        cal = calibrate([fitted(p) for p in pairs] if len(pairs) > 1 else fitted(pairs[0]), options=options)
        if len(pairs) == 1:
            seconds.append(time.perf_counter() - t0)
        return cal

    def predicted(cal, pair: Pair, row: str, mode: str, trained: str) -> None:
        pred = predict(cal, pair.filt, band=BAND)
        records.append({"row": row, "mode": mode, "train": trained, "test": pair.name,
                        **errors(pred, pair, residual),
                        "kept_fill_error": kept_fill_error(variant, pred, pair, payload)})

    rows = {"gravel": "gravel", "sand": "sand", "modified_sand": "modified_sand (unseen soil)",
            "dirt": "dirt (held-out soil)"}
    for soil, row in rows.items():
        pairs = test[soil]
        for i, train in enumerate(pairs):
            cal = cal_of([train])
            predicted(cal, train, row, "floor", train.name)
            for j, other in enumerate(pairs):
                if j != i:
                    predicted(cal, other, row, "one cycle", train.name)
            if soil == "gravel":
                predicted(cal, test["gravel_slope25"][0], ROWS[4], "one cycle", train.name)
        for i in range(len(pairs) - 1):
            two = [pairs[i], pairs[i + 1]]
            cal = cal_of(two)
            names = "+".join(p.name for p in two)
            for j, other in enumerate(pairs):
                if j not in (i, i + 1):
                    predicted(cal, other, row, "two cycles", names)
            if soil == "gravel":
                predicted(cal, test["gravel_slope25"][0], ROWS[4], "two cycles", names)
    slope = test["gravel_slope25"][0]
    predicted(cal_of([slope]), slope, ROWS[4], "floor", slope.name)
    return {"records": records, "calibration_s_median": float(np.median(seconds)), "calibrations": len(seconds)}


def summarise(result: dict) -> dict:
    out = {}
    for variant, res in result["variants"].items():
        rows = {}
        for row in (*ROWS, "all unseen"):
            def med(mode, key, row=row, records=res["records"]):
                vals = [r[key] for r in records if r["mode"] == mode and r.get(key) is not None
                        and (row == "all unseen" or r["row"] == row)]
                return float(np.median(vals)) if vals else None
            rows[row] = {"one_cycle": med("one cycle", "filtered"),
                         "one_cycle_unfiltered": med("one cycle", "unfiltered"),
                         "two_cycles": med("two cycles", "filtered"), "floor": med("floor", "filtered"),
                         "floor_unfiltered": med("floor", "unfiltered"),
                         "whole_record_one_cycle": med("one cycle", "whole_record"),
                         "band_coverage_one_cycle": med("one cycle", "band_coverage"),
                         "band_coverage_two_cycles": med("two cycles", "band_coverage"),
                         "kept_fill_error": med("one cycle", "kept_fill_error")}
        out[variant] = {"rows": rows, "calibration_s_median": res["calibration_s_median"]}
    return out


def table(result: dict) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.1f}"  # noqa: E731
    lines = ["| row | variant | one cycle | (unfiltered) | two cycles | floor | whole record, one cycle | "
             "90 % band, one / two cycles | kept fill error | calibration |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in ("all unseen", *ROWS):
        for variant, s in result["summary"].items():
            r = s["rows"][row]
            lines.append(f"| {row} | {variant} | {fmt(r['one_cycle'])} % | {fmt(r['one_cycle_unfiltered'])} % | "
                         f"{fmt(r['two_cycles'])} % | {fmt(r['floor'])} % | {fmt(r['whole_record_one_cycle'])} % | "
                         f"{fmt(r['band_coverage_one_cycle'])} / {fmt(r['band_coverage_two_cycles'])} % | "
                         f"{fmt(r['kept_fill_error'])} % | {s['calibration_s_median']:.2f} s |")
    return "\n".join(lines) + "\n"


def plot(result: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    modes = (("one_cycle", "one cycle"), ("two_cycles", "two cycles"), ("floor", "floor"))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), sharey=True)
    variants = list(result["summary"])
    rows = ("all unseen", *ROWS)
    width = 0.8 / len(variants)
    for ax, (key, title) in zip(axes, modes, strict=True):
        for k, variant in enumerate(variants):
            vals = [result["summary"][variant]["rows"][row][key] or 0.0 for row in rows]
            ax.bar(np.arange(len(rows)) + k * width, vals, width, label=variant)
        ax.axhline({"one_cycle": 15.0, "two_cycles": 12.0, "floor": 8.0}[key], color="k", ls="--", lw=1)
        ax.set_xticks(np.arange(len(rows)) + 0.4 - width / 2, [r.split(" (")[0] for r in rows], rotation=30)
        ax.set_title(f"{title} (dashed: target)")
    axes[0].set_ylabel("median F_R RMSE in soil [%], filtered")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/mpm"), help="folder of data/mpm's cycles (test)")
    parser.add_argument("--results", type=Path, default=Path("data/results"), help="folder of the saved loops (train)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    args = parser.parse_args()
    manifest = split(args.data, args.results)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    train = [Pair(p) for p in manifest["train"]]
    test = {k: [Pair(p) for p in v] for k, v in manifest["test"].items()}
    print(f"train {len(train)} cycles, test {sum(len(v) for v in test.values())}", flush=True)
    payload = fit_payload([p.raw for p in train])
    print(f"payload {payload}", flush=True)
    samples: list = []
    prior = data_prior(train, payload, samples)
    print(f"prior {prior}", flush=True)
    residual = fit_residual(samples)
    result = {"benchmark": "transfer", "sigma_s": SIGMA, "band": BAND, "payload": payload.to_dict(), "prior": prior,
              "residual": residual.to_dict(), "variants": {}, "machine": machine_info()}
    for variant in VARIANTS:
        result["variants"][variant] = evaluate(variant, options_for(variant, payload, prior), test, payload,
                                               residual if variant.endswith("residual") else None)
        print(f"{variant} done", flush=True)
    result["summary"] = summarise(result)
    (args.out / "transfer.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "table.md").write_text(table(result))
    plot(result, args.out / "transfer.png")
    print(table(result), end="")


if __name__ == "__main__":
    main()
