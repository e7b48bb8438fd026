"""Does a calibrated model carry over to paths it has not seen? The FEE against the payload model and data priors.

The data are the project's continuum (MPM) cycles, split by case family (soil x pile x path family), never by
sample (the split is written to ``manifest.json``):

* **train**: the saved MPM loops of the base and ``curlout`` runs (``data/results/adaptation_mpm/cycles``,
  ``adaptation_mpm_curlout/cycles``: gravel and sand, the loops' carved piles, the four strategies' paths).
  They give the data priors and the held prior (below) and, with the ``payload_extra`` cycles, the payload
  candidates; no validation or test cycle is in them.
* **validation**: the loops of the ``end55`` run (``data/results/adaptation_mpm_end55/cycles``: a path family
  of its own, the curl ending at 55 deg): within each loop, every cycle predicted from each other one and from
  each other pair of consecutive cycles. The choice among the payload candidates is made on them, and, with the
  ``band_validation`` groups, the band's width (``band_scale``, below); never on test.
* **band_validation**: the ``data/learn`` groups the shipped learned model holds out of its training (its
  manifest's ``validation_learn``: three smooth paths on one soil, pile and cutting edge each, the test's own
  protocol on an uncarved pile), predicted as the validation loops are. Only the band's width is made on them
  (with the loops); never on test. No variant trains on them (``data/learn`` is in ``payload_extra``: only a
  payload candidate may fit their kept fill).
* **payload_extra**: other MPM cycles with a logged kept fill (``data/learn``, the ``loop_mpm`` run, the plants'
  first cycles; test copies dropped by content): only the payload candidates that say so are fitted to them.

The payload (``fee-payload``'s kept soil, ``wheelloader.estimator.payload``) is the one of
:data:`PAYLOAD_CANDIDATES` whose kept fill predicts the validation cycles best: fitted to the training cycles
alone or with ``payload_extra``, along each path or at its end only, with or without the curl term (the heaped
capacity growing with the blade angle as the tip leaves the soil, ``PayloadOptions.curl_gain``), skipping or
not the cycles that keep more than 0.9 of what their carving removed (a logged start pile that is not the
surface the plant dug). Every candidate's test error is reported beside (``payload.md``), never used to choose.
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
* ``fee + held``, ``fee-payload + held``: fit only what a cycle can identify (``CalibrationOptions(held=)``,
  :class:`~wheelloader.estimator.calibration.HeldPrior`): the parameters whose total Sobol index reaches the
  threshold on the training families (``benchmarks/sensitivity.py``, recomputed here) are fitted; the others are
  held: gamma at the training soils' median input, K and n at the pair that predicts the training loops' next
  cycle best (the median one-cycle error over :data:`HELD_GRID`, each cycle k = 1, 3 of every training loop
  predicting cycle k + 1; ``fee-payload``; used for both models, whose in-soil forces are the same FEE);
* ``fee-payload + held, soft``: the same held parameters under a Gaussian prior at those means
  (:data:`HELD_SOFT_STD`: gamma 10 %, K 50 %, n 0.15) instead of fixed: a path that does determine them may
  move them;
* ``fee-payload-depth``: ``force_model="fee-payload-depth"`` (``fee-payload`` with N_gamma + k, k fitted to the
  training loops by ``benchmarks/model_form.py --fit-offset``) with the payload fitted to the training cycles;
* ``fee-payload + residual``: a learned correction beyond the FEE (``wheelloader.estimator.residual``, a ridge
  on dimensionless inputs) trained on the training cycles' residuals after their own ``fee-payload`` fits; the
  soil is fitted to the measured forces minus the residual, and the residual added to the prediction (the band
  shifted with it).

Reported per variant and row (soil or pile): the median F_R RMSE in soil (% of the mean observed |F_R| in soil)
of unseen paths predicted from ONE cycle, from TWO cycles (two neighbouring paths, the other two predicted), the
floor (each path fitted to itself), filtered and unfiltered; the whole-record error (every sample from the first
entry on, the carried load after the exit included); the 90 % band's coverage of the unseen paths' in-soil
samples; the kept fill's relative error at the path's end (the FEE's carved fill, the payload's kept soil,
against the plant's); the median calibration time of one cycle. The band's coverage is given three times: as the
calibration makes it (scale 1), scaled by the factor that makes the mean over the two validation families
(the loops, the ``band_validation`` groups) of their predictions' median coverage 90 %
(:func:`band_scale_families`, ``CalibrationOptions(band_scale=)``; per variant, one scale for one cycle and one for
two), and scaled on the validation loops alone (the rule before: a family whose one-cycle error is not the
test's, carved piles and a loop's consecutive cycles).
A band from two cycles takes its residual noise from each cycle predicted by a fit on the other
(:data:`TWO_CYCLE_BAND_NOISE`, ``band_noise="cross-cycle"``): the path-to-path error, which the training
residuals of a joint fit do not show and a scale alone did not carry from the validation loops to the test paths
(80 % coverage before, with the training residuals).

Run: ``python benchmarks/transfer.py --out docs/results/transfer`` (about 20 minutes at load 15; needs the
``model`` extra (SALib) for the held variants' Sobol rule; writes ``transfer.json``, ``manifest.json``, ``table.md``,
``validation.md``, ``payload.md`` and ``transfer.png``).
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from wheelloader.estimator import CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, HeldPrior, calibrate, predict
from wheelloader.estimator.payload import PayloadOptions, fit_payload, kept_fill, payload_contact_state
from wheelloader.estimator.residual import (
    ResidualModel,
    corrected_log,
    features,
    fit_residual,
    force_scale,
    residual_forces,
)
from wheelloader.estimator.soil_vector import SOIL_VECTOR_NAMES
from wheelloader.provenance import machine_info
from wheelloader.references.filtering import filtered

VARIANTS = ("fee", "fee-payload", "fee-payload + prior", "fee-payload + fixed phi, n", "fee-payload + input prior",
            "fee-payload + residual", "fee + held", "fee-payload + held", "fee-payload + held, soft", "fee-learned",
            "fee-payload-depth")
#: Widths of the soft held prior (``fee-payload + held, soft``): gamma 10 %, K 50 % of the held mean, n 0.15.
HELD_SOFT_STD = {"gamma": 0.1, "K": 0.5, "n": 0.15}
#: Candidate (K [N/m^(n+2)], n) of the held prior; the one predicting the training loops best is kept.
HELD_GRID = [(k, n) for k in (3.0e4, 1.0e5, 3.0e5, 1.0e6, 3.0e6) for n in (0.9, 1.2, 1.5)]
#: Standard deviation of the input prior (the training soils' own parameters are known exactly; their spread
#: across soils is what a new soil may differ by): phi and delta 5 deg, n 0.15.
INPUT_PRIOR_STD = {"phi": math.radians(5.0), "delta": math.radians(5.0), "n": 0.15}
PRIOR_NAMES = ("phi", "delta", "n")
ROWS = ("gravel", "sand", "modified_sand (unseen soil)", "dirt (held-out soil)", "25 deg pile (held-out pile)")
SIGMA = 0.1
BAND = 0.9
MODES = ("one cycle", "two cycles")
#: Folders of MPM cycles beyond train and validation that carry a kept fill: candidates for the payload's fit only
#: (``{data}``: the folder above ``--data``, ``{results}``: ``--results``); test copies are dropped by content.
PAYLOAD_EXTRA = ("{data}/learn", "{results}/loop_mpm/cycles", "{results}/plant_first_cycle/cycles")
#: The band's residual noise from two cycles: each cycle predicted by a fit on the other (leave one cycle out,
#: ``CalibrationOptions(band_noise="cross-cycle")``): the path-to-path error the training residuals do not show.
TWO_CYCLE_BAND_NOISE = "cross-cycle"
#: The payload candidates (module docstring): which cycles, where along them, the curl term, the skip rule.
PAYLOAD_CANDIDATES = [{"cycles": cycles, "samples": samples, "curl": curl, "max_kept_ratio": ratio}
                      for cycles in ("train", "train + extra") for samples in ("path", "end")
                      for curl in (False, True) for ratio in (None, 0.9)]


#: Folders under the loop_mpm run's cycles that hold the RL runs dug beside it after the shipped split was made
#: (the fee-payload policy, the closed-loop policies): not payload candidates until the next regeneration.
EXTRA_EXCLUDED = ("rl_payload", "rl_closed")


def _is_payload_extra(path: Path) -> bool:
    """Whether a saved cycle is a payload candidate: not in :data:`EXTRA_EXCLUDED`, and a learning-set cycle only
    once its generator's ``manifest.json`` lists it (a cycle still being dug, or copied without its entry, is not
    part of the set)."""
    if any(part in EXTRA_EXCLUDED for part in path.parts):
        return False
    listed = _learning_set_listed(path.parent) if path.parent.name == "learn" else None
    return listed is None or path.name in listed


@functools.cache
def _learning_set_listed(folder: Path) -> frozenset[str] | None:
    """The cycle files a learning set's ``manifest.json`` lists (read once per folder), or None without one."""
    manifest = folder / "manifest.json"
    if not manifest.is_file():
        return None
    return frozenset(Path(c["csv"]).name for c in json.loads(manifest.read_text())["cycles"])


def split(data: Path, results: Path) -> dict:
    """The train/validation/test split by case family (module docstring)."""
    train = sorted(str(p) for run in ("adaptation_mpm", "adaptation_mpm_curlout")
                   for p in (results / run / "cycles").glob("**/*.csv.xz"))
    validation = sorted(str(p) for p in (results / "adaptation_mpm_end55" / "cycles").glob("**/*.csv.xz"))
    test = {soil: [str(data / f"{soil}_path{i}.csv") for i in range(1, 5)]
            for soil in ("gravel", "sand", "modified_sand", "dirt")}
    test["gravel_slope25"] = [str(data / "gravel_slope25_path1.csv")]
    # a loop's first fixed (and oracle) cycle on the start pile is the very cycle data/mpm ships as path 1:
    # such copies are dropped from train and validation by content, so no test cycle is trained on
    test_digests = {CycleLog.load(f).content_digest() for files in test.values() for f in files}
    dropped = [f for f in train + validation if CycleLog.load(f).content_digest() in test_digests]
    extra = sorted(str(p) for folder in PAYLOAD_EXTRA for p in Path(folder.format(data=data.parent, results=results))
                   .glob("**/*.csv.xz") if _is_payload_extra(p))
    dropped += [f for f in extra if CycleLog.load(f).content_digest() in test_digests]
    train = [f for f in train if f not in dropped]
    validation = [f for f in validation if f not in dropped]
    extra = [f for f in extra if f not in dropped]
    return {"rule": "split by case family (soil x pile x path family); train: the saved MPM loops of the base and "
                    "curlout runs (gravel, sand; their carved piles; the loops' strategies); validation: the loops "
                    "of the end55 run (its own path family; the payload recipe is chosen on it); band_validation: "
                    "the data/learn groups the shipped learned model holds out of its training (smooth paths on "
                    "an uncarved pile, three per soil, pile and edge; the band's width is chosen on them); test: "
                    "data/mpm's four smooth paths on the trapezoid pile; held out of training and validation "
                    "entirely: the soils modified_sand and dirt, the 25 deg pile; payload_extra: other MPM cycles "
                    "with a logged kept fill (the learning set, the loop_mpm run, the plants' first cycles), which "
                    "only a payload candidate may be fitted to",
            "train": train, "validation": validation, "band_validation": band_validation(data), "test": test,
            "payload_extra": extra, "dropped_as_test_copies": dropped}


def band_validation(data: Path) -> dict[str, list[str]]:
    """The ``data/learn`` groups (under the folder above ``data``) the shipped learned model holds out of its
    training (its manifest's ``validation_learn``), each a list of its cycles' files."""
    from wheelloader.estimator.learned import default_learned_model

    held = default_learned_model().manifest["split"]["validation_learn"]
    learn = data.parent / "learn"
    return {group: [str(learn / Path(f).name) for f in files] for group, files in sorted(held.items())}



class Pair:
    """A cycle's raw and filtered log."""

    def __init__(self, path: str):
        self.path = path
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


def loops(pairs: list[Pair]) -> list[list[Pair]]:
    """The cycles grouped by loop (their folder), each loop's cycles in order."""
    out: dict[str, list[Pair]] = {}
    for pair in sorted(pairs, key=lambda p: p.path):
        out.setdefault(str(Path(pair.path).parent), []).append(pair)
    return list(out.values())


def free_sets(train: list[Pair], payload: PayloadOptions) -> dict:
    """Which parameters to fit from one and from several cycles: the Sobol rule of ``benchmarks/sensitivity.py``
    on the training families (the first and third cycle of each gravel training loop, seed 0, and its cycles
    1 + 2 joined)."""
    import importlib.util

    from wheelloader.estimator.calibration.sensitivity import sobol_indices
    from wheelloader.estimator.force_models import cycle_contact_state

    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_sensitivity",
                                                  Path(__file__).with_name("sensitivity.py"))
    sens = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(sens)
    opts = CalibrationOptions(force_model="fee-payload", payload=payload)
    rows = []
    for loop in loops(train):
        if "/gravel/seed0/" not in loop[0].path:
            continue
        for cycles in ([loop[0]], [loop[2]], loop[:2]):
            states = [cycle_contact_state(p.filt, opts.force_model, opts.payload, opts.slope_window, opts.fill)
                      for p in cycles]
            res = sobol_indices(states, cycles[0].raw.bucket, opts.model_options, base=sens.BASE, points=sens.POINTS)
            rows.append({"split": "train", "cycles": len(cycles), "total": res.total})
    one, several = sens.rule(rows, 1), sens.rule(rows, 2)
    free_several = [n for n in SOIL_VECTOR_NAMES if n in one["free"] or n in several["free"]]
    return {"threshold": sens.THRESHOLD, "one_cycle": one, "several_cycles": several, "free_one": one["free"],
            "free_several": free_several}


def held_prior(train: list[Pair], payload: PayloadOptions, free: dict) -> dict:
    """The held prior's means (module docstring): inputs' medians; K and n by the training loops' next cycle."""
    inputs = {name: float(np.median([pair.raw.metadata["soil_params"][name] for pair in train]))
              for name in ("gamma", "cohesion", "adhesion", "phi", "delta", "n")}
    b = train[0].raw.bucket.edge_thickness
    inputs["K"] = float(np.median([pair.raw.metadata["soil_params"]["k_c"] / b
                                   + pair.raw.metadata["soil_params"]["k_phi"] for pair in train]))
    pairs = [(loop[k], loop[k + 1]) for loop in loops(train) for k in (0, 2) if len(loop) > k + 1]
    scores = []
    for k_value, n_value in HELD_GRID:
        held = HeldPrior(inputs | {"K": k_value, "n": n_value}, free_one=tuple(free["free_one"]),
                         free_several=tuple(free["free_several"]))
        opts = CalibrationOptions(force_model="fee-payload", payload=payload, held=held)
        errs = []
        for a, b_pair in pairs:
            try:
                cal = calibrate(a.filt, options=opts)
            except Exception:  # a loop cycle the calibration refuses (too few in-soil samples)
                continue
            errs.append(errors(predict(cal, b_pair.filt), b_pair)["filtered"])
        scores.append(float(np.median(errs)))
        print(f"  held K {k_value:.3g}, n {n_value}: training next-cycle error {scores[-1]:.1f} %", flush=True)
    best = HELD_GRID[int(np.argmin(scores))]
    mean = inputs | {"K": best[0], "n": best[1]}
    return {"held": HeldPrior(mean, free_one=tuple(free["free_one"]),
                              free_several=tuple(free["free_several"])).to_dict(),
            "inputs_median": inputs, "grid": [{"K": k, "n": n, "median_error": e}
                                              for (k, n), e in zip(HELD_GRID, scores, strict=True)],
            "training_pairs": len(pairs)}


def options_for(variant: str, payload: PayloadOptions, prior: dict) -> CalibrationOptions:
    if variant == "fee-learned":  # the shipped artifact, with its payload (built from this benchmark's choice)
        return CalibrationOptions(force_model="fee-learned")
    if variant == "fee-payload-depth":  # its N_gamma offset fitted to the training loops (benchmarks/model_form.py)
        return CalibrationOptions(force_model="fee-payload-depth", payload=payload)
    if variant.endswith("held, soft"):
        held = HeldPrior.from_dict(prior["held"]["held"])
        mean = held.mean
        std = {"gamma": HELD_SOFT_STD["gamma"] * mean["gamma"], "K": HELD_SOFT_STD["K"] * mean["K"],
               "n": HELD_SOFT_STD["n"]}
        held = HeldPrior(mean, std=std, free_one=held.free_one, free_several=held.free_several)
        return CalibrationOptions(force_model="fee-payload", payload=payload, held=held)
    if variant.endswith("+ held"):
        held = HeldPrior.from_dict(prior["held"]["held"])
        if variant.startswith("fee-payload"):
            return CalibrationOptions(force_model="fee-payload", payload=payload, held=held)
        return CalibrationOptions(fill="model", held=held)
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


def band_ratio(pred, observed_r: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """``|observed - predicted| / (z std)`` of F_R per in-soil sample, ``std`` the band's own (its calibration's
    ``band_scale`` included): the band holds a sample iff its ratio is <= 1."""
    centre = np.hypot(pred.tangential, pred.normal)
    width = np.maximum(pred.band.upper_r - centre, 1e-12)
    return np.abs(observed_r - centre)[inside] / width[inside]


def errors(pred, pair: Pair, residual: ResidualModel | None = None, scale: float = 1.0) -> dict:
    """In-soil F_R RMSE (filtered, unfiltered), the whole record's, and the band's coverage (filtered).

    ``scale``: the band's ``band_scale`` (its calibration's); ``band_coverage`` is the coverage at that scale,
    ``band_coverage_raw`` at scale 1, ``band_ratios`` the samples' ratios at scale 1 (:func:`band_ratio`).
    """
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
        scale_f = float(np.mean(obs[inside]))
        out[key] = 100.0 * math.sqrt(float(np.mean((pr[inside] - obs[inside]) ** 2))) / scale_f
        if key == "filtered":
            whole = np.arange(len(obs)) >= int(np.flatnonzero(inside)[0])
            out["whole_record"] = 100.0 * math.sqrt(float(np.mean((pr[whole] - obs[whole]) ** 2))) / scale_f
            if pred.band is not None:
                ratio = band_ratio(pred, obs - shift, inside) * scale
                out["band_coverage"] = 100.0 * float(np.mean(ratio <= scale))
                out["band_coverage_raw"] = 100.0 * float(np.mean(ratio <= 1.0))
                out["band_ratios"] = ratio
    return out


def kept_fill_error(variant: str, pred, pair: Pair, payload: PayloadOptions) -> float | None:
    """Relative error [%] of the predicted kept fill at the path's end against the plant's logged fill."""
    if pair.raw.fill_volume is None or pair.raw.fill_volume[-1] <= 0.0:
        return None
    cap = pair.raw.bucket.capacity
    model = (float(pred.state.fill_volume[-1]) if variant == "fee"
             else kept_fill(pred.state, cap, payload, blade_angle=pair.raw.path.blade_angle))
    return 100.0 * abs(model - float(pair.raw.fill_volume[-1])) / float(pair.raw.fill_volume[-1])


def _kept_errors(payload: PayloadOptions, cycles: list[tuple[CycleLog, object]]) -> list[float]:
    """Relative kept fill errors [%] at the paths' ends of ``(log, carved contact state)`` pairs."""
    return [100.0 * abs(kept_fill(state, log.bucket.capacity, payload, blade_angle=log.path.blade_angle)
                        - float(log.fill_volume[-1])) / float(log.fill_volume[-1]) for log, state in cycles]


def select_payload(train: list[Pair], extra: list[CycleLog], validation: list[Pair],
                   test: dict[str, list[Pair]]) -> tuple[PayloadOptions, dict]:
    """Fit every :data:`PAYLOAD_CANDIDATES` recipe and keep the one whose kept fill predicts the validation
    cycles best (median relative error at the path's end); the test errors of every candidate are reported
    beside, never used to choose."""
    def carved(logs: list[CycleLog]) -> list[tuple[CycleLog, object]]:
        return [(log, log.contact_state(fill="model")) for log in logs
                if log.fill_volume is not None and log.fill_volume[-1] > 0.0]

    checks = {"validation": carved([p.raw for p in validation]),
              "test": carved([p.raw for pairs in test.values() for p in pairs])}
    rows = []
    for cand in PAYLOAD_CANDIDATES:
        logs = [p.raw for p in train] + (extra if cand["cycles"] == "train + extra" else [])
        free = ("retention", "heap_factor", "sharpness") + (("curl_gain",) if cand["curl"] else ())
        payload = fit_payload(logs, free=free, samples=cand["samples"], max_kept_ratio=cand["max_kept_ratio"])
        row = {**cand, "payload": payload.to_dict()}
        for key, cycles in checks.items():
            errs = _kept_errors(payload, cycles)
            row[f"{key}_median"], row[f"{key}_max"] = float(np.median(errs)), float(np.max(errs))
        rows.append(row)
        print(f"  payload {cand}: validation {row['validation_median']:.2f} %, test {row['test_median']:.2f} %",
              flush=True)
    best = min(range(len(rows)), key=lambda k: rows[k]["validation_median"])
    rows[best]["chosen"] = True
    return PayloadOptions.from_dict(rows[best]["payload"]), {"candidates": rows, "chosen": best,
                                                             "extra_cycles": len(extra),
                                                             "dependence": retention_dependence(train, extra)}


def retention_dependence(train: list[Pair], extra: list[CycleLog]) -> list[dict]:
    """What the kept fill depends on beyond the removed volume: the plain payload (no curl term) fitted at the
    paths' ends of the training and extra cycles (those keeping at most 0.9 of what they removed), and the
    Pearson correlation of its relative miss ``observed / model - 1`` per cycle with candidate quantities."""
    logs = [p.raw for p in train] + extra
    payload = fit_payload(logs, samples="end", max_kept_ratio=0.9)
    rows = []
    for log in logs:
        state = log.contact_state(fill="model")
        removed, kept = float(state.carve.removed_history[-1]), float(log.fill_volume[-1])
        if kept <= 0.0 or kept > 0.9 * removed:
            continue
        inside = np.flatnonzero(state.depth > 0.0)
        model = kept_fill(state, log.bucket.capacity, payload)
        rows.append([kept / model - 1.0, math.degrees(log.path.blade_angle[inside[-1]]),
                     math.degrees(log.path.blade_angle[-1]), float(state.depth.max()) / log.bucket.floor_length,
                     removed / log.bucket.capacity, float(log.path.t[inside[-1]] - log.path.t[inside[0]])])
    arr = np.array(rows)
    names = ("blade angle as the tip leaves the soil [deg]", "blade angle at the path's end [deg]",
             "deepest cut / floor length", "removed volume / capacity", "time in soil [s]")
    return [{"quantity": name, "correlation": float(np.corrcoef(arr[:, 0], arr[:, k + 1])[0, 1]),
             "cycles": int(arr.shape[0]), "range": [float(arr[:, k + 1].min()), float(arr[:, k + 1].max())]}
            for k, name in enumerate(names)]


def payload_table(result: dict) -> str:
    """The payload candidates: validation (the choice) and test (reported) kept fill errors."""
    lines = ["| cycles | samples | curl term | skip kept > 0.9 removed | r | h | p | g | validation median / max | "
             "test median / max |", "|---|---|---|---|---|---|---|---|---|---|"]
    for row in result["payload_selection"]["candidates"]:
        p = row["payload"]
        mark = " **(chosen)**" if row.get("chosen") else ""
        lines.append(f"| {row['cycles']}{mark} | {row['samples']} | {'yes' if row['curl'] else 'no'} | "
                     f"{'yes' if row['max_kept_ratio'] else 'no'} | {p['retention']:.3f} | {p['heap_factor']:.3f} | "
                     f"{p['sharpness']:.2f} | {p.get('curl_gain', 0.0):.3f} | {row['validation_median']:.1f} / "
                     f"{row['validation_max']:.1f} % | {row['test_median']:.1f} / {row['test_max']:.1f} % |")
    dep = result["payload_selection"]["dependence"]
    lines += ["", f"What the plain payload's miss at the path's end (observed / model - 1; fitted at the ends of the "
                  f"{dep[0]['cycles']} training and extra cycles that keep at most 0.9 of what they removed) "
                  "correlates with:", "", "| quantity | range | correlation |", "|---|---|---|"]
    lines += [f"| {d['quantity']} | {d['range'][0]:.2f} to {d['range'][1]:.2f} | {d['correlation']:+.2f} |"
              for d in dep]
    return "\n".join(lines) + "\n"


def fitted_log(pair: Pair, residual: ResidualModel | None, payload: PayloadOptions) -> CycleLog:
    """The log a variant calibrates on: the filtered log, minus the residual for the residual variant."""
    if residual is None:
        return pair.filt
    return corrected_log(residual, payload_contact_state(pair.filt, payload), pair.filt)


def validate(options: CalibrationOptions, validation: list[list[Pair]], payload: PayloadOptions,
             residual: ResidualModel | None = None) -> list[dict]:
    """The validation predictions (module docstring): each loop's cycles from each other cycle and each other
    pair of consecutive cycles; per prediction its mode, F_R error and band ratios (:func:`band_ratio`, scale 1)."""
    out = []
    for loop in validation:
        groups = [[p] for p in loop] + [loop[i:i + 2] for i in range(len(loop) - 1)]
        for group in groups:
            logs = [fitted_log(p, residual, payload) for p in group]
            try:
                cal = calibrate(logs if len(logs) > 1 else logs[0],
                                options=options if len(logs) == 1 else replace(options,
                                                                               band_noise=TWO_CYCLE_BAND_NOISE))
            except Exception:  # a loop cycle the calibration refuses (too few in-soil samples)
                continue
            for other in loop:
                if other not in group:
                    e = errors(predict(cal, other.filt, band=BAND), other, residual, options.band_scale)
                    out.append({"mode": "one cycle" if len(group) == 1 else "two cycles", "filtered": e["filtered"],
                                "ratios": e["band_ratios"]})
    return out


def band_scale_families(families: list[list[dict]], level: float = BAND) -> float:
    """Smallest band scale at which the mean over ``families`` of the median coverage of their validation
    predictions reaches ``level``: each family weighs the same, however many predictions it holds (one family:
    :func:`band_scale`)."""
    families = [f for f in families if f]

    def mean_coverage(k: float) -> float:
        return float(np.mean([np.median([np.mean(r["ratios"] <= k) for r in f]) for f in families]))

    lo, hi = 0.01, 100.0
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if mean_coverage(mid) >= level else (mid, hi)
    return hi


def band_scale(records: list[dict], level: float = BAND) -> float:
    """Smallest band scale whose median coverage over the validation predictions reaches ``level``."""
    def median_coverage(k: float) -> float:
        return float(np.median([np.mean(r["ratios"] <= k) for r in records]))

    lo, hi = 0.01, 100.0
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        lo, hi = (lo, mid) if median_coverage(mid) >= level else (mid, hi)
    return hi


def validation_summary(records: list[dict], scales: tuple[float, float]) -> dict:
    out = {"band_scale_one_cycle": scales[0], "band_scale_two_cycles": scales[1], "predictions": len(records)}
    for mode, key, scale in (("one cycle", "one_cycle", scales[0]), ("two cycles", "two_cycles", scales[1])):
        sel = [r for r in records if r["mode"] == mode]
        out[key] = float(np.median([r["filtered"] for r in sel]))
        out[f"band_coverage_raw_{key}"] = 100.0 * float(np.median([np.mean(r["ratios"] <= 1.0) for r in sel]))
        out[f"band_coverage_{key}"] = 100.0 * float(np.median([np.mean(r["ratios"] <= scale) for r in sel]))
    return out


def evaluate(variant: str, options: CalibrationOptions, test: dict[str, list[Pair]], payload: PayloadOptions,
             residual: ResidualModel | None = None, scales: tuple[float, float] = (1.0, 1.0),
             loop_scales: tuple[float, float] | None = None) -> dict:
    """The test predictions; ``scales``: the band's scale from one cycle and from two (band validation);
    ``loop_scales``: the same from the validation loops alone (the rule before), whose coverage is reported
    beside (``band_coverage_loops``)."""
    records = []
    seconds = []
    by_count = (replace(options, band_scale=scales[0]),
                replace(options, band_scale=scales[1], band_noise=TWO_CYCLE_BAND_NOISE))

    def fitted(pair: Pair):
        return fitted_log(pair, residual, payload)

    def cal_of(pairs: list[Pair]):
        t0 = time.perf_counter()
        cal = calibrate([fitted(p) for p in pairs] if len(pairs) > 1 else fitted(pairs[0]),
                        options=by_count[len(pairs) > 1])
        if len(pairs) == 1:
            seconds.append(time.perf_counter() - t0)
        return cal

    def predicted(cal, pair: Pair, row: str, mode: str, trained: str) -> None:
        pred = predict(cal, pair.filt, band=BAND)
        e = errors(pred, pair, residual, cal.band_model.scale)
        ratios = e.pop("band_ratios", None)
        if ratios is not None and loop_scales is not None:
            k = loop_scales[mode == "two cycles"]
            e["band_coverage_loops"] = 100.0 * float(np.mean(ratios <= k))
        records.append({"row": row, "mode": mode, "train": trained, "test": pair.name, **e,
                        "kept_fill_error": kept_fill_error(variant, pred, pair, options.payload or payload),
                        "outside_training": None if pred.outside_training is None else
                        100.0 * float(np.mean(pred.outside_training[pred.state.depth > 0.0]))})

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


def check_learned_split(manifest: dict) -> None:
    """Refuse to judge the shipped learned model on a cycle it was trained on."""
    from wheelloader.estimator.learned import default_learned_model

    learned = default_learned_model().manifest["split"]
    trained = {Path(f).resolve() for files in learned["train"].values() for f in files}
    tested = {Path(f).resolve() for files in manifest["test"].values() for f in files}
    if trained & tested:
        raise SystemExit(f"wheelloader: error: the learned model was trained on test cycles {sorted(trained & tested)}")


def learned_payload_check(payload: PayloadOptions) -> dict:
    """Whether the shipped learned model keeps the payload chosen here (``benchmarks/fee_learned.py`` builds it
    with this benchmark's choice; a rebuild is due where the data changed since)."""
    from wheelloader.estimator.learned import default_learned_model

    shipped = default_learned_model().payload
    same = all(math.isclose(getattr(shipped, f), getattr(payload, f), rel_tol=1e-9, abs_tol=1e-12)
               for f in ("retention", "heap_factor", "sharpness", "curl_gain"))
    if not same:
        print(f"  note: fee-learned keeps the payload {shipped}, not the one chosen here: rebuild its weights "
              "(python benchmarks/fee_learned.py --out estimator/learned_weights)", flush=True)
    return {"payload": shipped.to_dict(), "is_the_chosen_one": same}


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
                         "band_coverage_raw_one_cycle": med("one cycle", "band_coverage_raw"),
                         "band_coverage_raw_two_cycles": med("two cycles", "band_coverage_raw"),
                         "band_coverage_loops_one_cycle": med("one cycle", "band_coverage_loops"),
                         "band_coverage_loops_two_cycles": med("two cycles", "band_coverage_loops"),
                         "kept_fill_error": med("one cycle", "kept_fill_error")}
        v = res["validation"]
        out[variant] = {"rows": rows, "calibration_s_median": res["calibration_s_median"],
                        "band_scales": [v["band_scale_one_cycle"], v["band_scale_two_cycles"]],
                        "loop_band_scales": res.get("loop_only_band_scales", [v["band_scale_one_cycle"],
                                                                              v["band_scale_two_cycles"]]),
                        "validation": v, "band_validation": res.get("band_validation")}
    return out


def table(result: dict) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.1f}"  # noqa: E731
    lines = ["| row | variant | one cycle | (unfiltered) | two cycles | floor | whole record, one cycle | "
             "90 % band, one / two cycles (scale 1) | 90 % band scaled on validation (loops and smooth groups), one / "
             "two (scales) | the same scaled on the loops alone (scales) | kept fill error | calibration |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in ("all unseen", *ROWS):
        for variant, s in result["summary"].items():
            r = s["rows"][row]
            lines.append(f"| {row} | {variant} | {fmt(r['one_cycle'])} % | {fmt(r['one_cycle_unfiltered'])} % | "
                         f"{fmt(r['two_cycles'])} % | {fmt(r['floor'])} % | {fmt(r['whole_record_one_cycle'])} % | "
                         f"{fmt(r['band_coverage_raw_one_cycle'])} / {fmt(r['band_coverage_raw_two_cycles'])} % | "
                         f"{fmt(r['band_coverage_one_cycle'])} / {fmt(r['band_coverage_two_cycles'])} % "
                         f"({s['band_scales'][0]:.2f} / {s['band_scales'][1]:.2f}) | "
                         f"{fmt(r.get('band_coverage_loops_one_cycle'))} / "
                         f"{fmt(r.get('band_coverage_loops_two_cycles'))} % "
                         f"({s['loop_band_scales'][0]:.2f} / {s['loop_band_scales'][1]:.2f}) | "
                         f"{fmt(r['kept_fill_error'])} % | "
                         f"{s['calibration_s_median']:.2f} s |")
    return "\n".join(lines) + "\n"


def validation_table(result: dict) -> str:
    """The validation families, each at the band's scales (made on both): the loops (end55: also the payload
    recipe) and the smooth groups."""
    lines = ["| family | variant | one cycle | two cycles | 90 % band, one / two cycles (scale 1) | band scale, one / "
             "two | scaled band, one / two cycles | predictions |", "|---|---|---|---|---|---|---|---|"]
    for family, key in (("loops (end55)", "validation"), ("smooth groups", "band_validation")):
        for variant, s in result["summary"].items():
            if s.get(key):
                lines.append(_validation_row(family, variant, s[key]))
    return "\n".join(lines) + "\n"


def _validation_row(family: str, variant: str, v: dict) -> str:
    return (f"| {family} | {variant} | {v['one_cycle']:.1f} % | {v['two_cycles']:.1f} % | "
            f"{v['band_coverage_raw_one_cycle']:.1f} / {v['band_coverage_raw_two_cycles']:.1f} % | "
            f"{v['band_scale_one_cycle']:.2f} / {v['band_scale_two_cycles']:.2f} | "
            f"{v['band_coverage_one_cycle']:.1f} / {v['band_coverage_two_cycles']:.1f} % | {v['predictions']} |")


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
    parser.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS),
                        help="variants to run (default all; the priors, held sets and residual are fitted only if run)")
    args = parser.parse_args()
    manifest = split(args.data, args.results)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    check_learned_split(manifest)
    train = [Pair(p) for p in manifest["train"]]
    validation = loops([Pair(p) for p in manifest["validation"]])
    band_groups = [[Pair(p) for p in files] for files in manifest["band_validation"].values()]
    test = {k: [Pair(p) for p in v] for k, v in manifest["test"].items()}
    print(f"train {len(train)} cycles, validation {sum(len(v) for v in validation)}, "
          f"test {sum(len(v) for v in test.values())}", flush=True)
    extra = [CycleLog.load(p) for p in manifest["payload_extra"]]
    payload, selection = select_payload(train, extra, [p for loop in validation for p in loop], test)
    print(f"payload {payload}", flush=True)
    learned_payload = learned_payload_check(payload) if "fee-learned" in args.variants else None
    samples: list = []
    prior, residual = None, None
    if any("+" in v for v in args.variants):
        prior = data_prior(train, payload, samples)
        print(f"prior {prior}", flush=True)
        residual = fit_residual(samples)
    if any("held" in v for v in args.variants):
        free = free_sets(train, payload)
        print(f"free {free['free_one']} (one cycle), {free['free_several']} (several)", flush=True)
        prior["held"] = held_prior(train, payload, free)
        prior["held"]["sobol"] = free
        print(f"held {prior['held']['held']}", flush=True)
    result = {"benchmark": "transfer", "sigma_s": SIGMA, "band": BAND, "payload": payload.to_dict(),
              "payload_selection": selection, "fee_learned_payload": learned_payload,
              "two_cycle_band_noise": TWO_CYCLE_BAND_NOISE, "prior": prior,
              "residual": None if residual is None else residual.to_dict(), "variants": {}, "machine": machine_info()}
    for variant in args.variants:
        options = options_for(variant, payload, prior)
        res = residual if variant.endswith("residual") else None
        checks = validate(options, validation, payload, res)
        loop_scales = tuple(band_scale([c for c in checks if c["mode"] == mode]) for mode in MODES)
        band_checks = validate(options, band_groups, payload, res)
        scales = tuple(band_scale_families([[c for c in fam if c["mode"] == mode] for fam in (checks, band_checks)])
                       for mode in MODES)
        result["variants"][variant] = evaluate(variant, options, test, payload, res, scales, loop_scales)
        result["variants"][variant]["validation"] = validation_summary(checks, scales)
        result["variants"][variant]["band_validation"] = validation_summary(band_checks, scales)
        result["variants"][variant]["loop_only_band_scales"] = list(loop_scales)
        print(f"{variant} done: band scales {scales[0]:.3f} (one cycle), {scales[1]:.3f} (two); on the loops "
              f"{loop_scales[0]:.3f}, {loop_scales[1]:.3f}", flush=True)
    result["summary"] = summarise(result)
    (args.out / "transfer.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "table.md").write_text(table(result))
    (args.out / "validation.md").write_text(validation_table(result))
    (args.out / "payload.md").write_text(payload_table(result))
    plot(result, args.out / "transfer.png")
    print(table(result), end="")


if __name__ == "__main__":
    main()
