"""Where the force model misses a reference: the error by phase of the cycle and by term of the model.

For each prediction of the paper's experiments (calibrate on one cycle, predict another; our method by
default), the in-soil samples are split into phases of the cycle and the F_R error is booked per phase:

* ``entry``: the tip is in the soil and has not yet reached 90 % of the cycle's maximum depth;
* ``deep cut``: after that, while the blade angle to the surface rho is at least ``--curl-rho`` (20 deg);
* ``curl``: rho below that (the bucket rotates up; the model clamps rho at its lower bound);

(samples with the tip above the surface are not in the RMSE, as in the estimator; their mean measured
F_R is reported beside, the carried load the model does not have).

Which term carries the error: the residual (measured - predicted F_T and F_N, filtered reference) of each
phase is projected on the blade-frame force of each model term (eq 1 split into gamma, c, c_a and the
surcharge W_load N_q terms; the Bekker penetration term and the blade adhesion of eq 16) and on one
term the model does not have, the weight of the soil in the bucket (``rho_ref g V_fill`` pointing down,
from the reference's own fill). The share of the residual's sum of squares a scaled copy of one term
removes (R^2 of a one-parameter fit) says which term's shape the error has: a model term with a high
share is mis-scaled in that phase (a calibration compromise), the carried load with a high share is
the missing physics.

Every force model of ``--force-models`` (default: all of :data:`~wheelloader.estimator.FORCE_MODELS`) is
calibrated (our method) and analysed side by side, the FEE first: for ``"fee-payload"`` and ``"fee-learned"``
the model's own carried load is a term (and the reference-fill weight stays as the diagnostic), for
``"fee-learned"`` the learned correction is a term of its own. Beside the in-soil error, the error *after exit*
(tip above the surface, soil still in the bucket, which the FEE predicts as zero) and the RMSE against the
unfiltered record. The JSON records the learned weights used (version, SHA-256 of the artifact) and keeps the
plotted series subsampled (every ``SERIES_STRIDE``-th sample, rounded) so that it stays small.

Run: ``python benchmarks/error_analysis.py --data data/mpm --out docs/results/error_mpm``.
Writes ``error_analysis.json``, ``error_analysis.md``, ``models.md`` (the models side by side),
``phases.png`` and ``terms.png``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
from pathlib import Path

import numpy as np

from wheelloader.estimator import FORCE_MODELS, GRAVITY
from wheelloader.provenance import commit_label, machine_info

PHASES = ("entry", "deep cut", "curl")
TERMS = ("gamma", "cohesion", "adhesion", "surcharge", "penetration", "blade adhesion", "carried load (missing)")
#: The terms of the models with the payload as a state: the model's carried load is a term, the reference-fill
#: weight stays as the diagnostic; ``"fee-learned"`` adds its correction.
PAYLOAD_TERMS = TERMS[:-1] + ("carried load (model)", "carried load (reference fill)")
LEARNED_TERMS = PAYLOAD_TERMS + ("learned correction",)
#: Every n-th sample of the plotted series is kept in the JSON (rounded to 0.1 N, 1 ms).
SERIES_STRIDE = 2


def model_terms(force_model: str) -> tuple[str, ...]:
    """The term names booked for ``force_model``."""
    return {"fee": TERMS, "fee-payload": PAYLOAD_TERMS, "fee-learned": LEARNED_TERMS}[force_model]


def learned_artifact() -> dict:
    """Which learned weights ``"fee-learned"`` used: path, version, SHA-256 of the file, the split's rule."""
    from wheelloader.estimator.learned import DEFAULT_ARTIFACT, default_learned_model

    model = default_learned_model()
    split = (model.manifest or {}).get("split")
    rule = split.get("rule") if isinstance(split, dict) else None
    return {"path": "/".join(Path(DEFAULT_ARTIFACT).parts[-3:]), "version": model.version,
            "sha256": hashlib.sha256(Path(DEFAULT_ARTIFACT).read_bytes()).hexdigest(), "split_rule": rule}
#: (training cycle, predicted cycle, label) of the paper's experiments, as in paper_experiments.py.
CASES = (
    ("gravel_path1", "gravel_path1", "gravel path 1 (training)"),
    ("gravel_path1", "gravel_path2", "gravel path 2 (unseen)"),
    ("gravel_path1", "gravel_path3", "gravel path 3 (unseen)"),
    ("gravel_path1", "gravel_path4", "gravel path 4 (unseen)"),
    ("gravel_dual_cycle1", "gravel_dual_cycle2", "gravel dual cycle 2"),
    ("gravel_path1", "gravel_slope25_path1", "gravel path 1, 25 deg pile (unseen)"),
    ("modified_sand_path1", "modified_sand_path1", "modified sand path 1 (training)"),
    ("dirt_path1", "dirt_path1", "dirt path 1 (training)"),
    ("sand_path1", "sand_path1", "sand path 1 (training)"),
)


def phases_of(state, curl_rho: float) -> dict[str, np.ndarray]:
    """Boolean masks of the in-soil phases (see the module docstring)."""
    inside = state.depth > 0.0
    if not np.any(inside):
        return {p: np.zeros_like(inside) for p in PHASES}
    deepest = float(np.max(state.depth))
    reached = int(np.argmax(state.depth >= 0.9 * deepest))
    before = np.arange(state.depth.size) < reached
    curl = inside & ~before & (state.rho < curl_rho)
    return {"entry": inside & before, "deep cut": inside & ~before & ~curl, "curl": curl}


def term_forces(pred, bucket, density: float, contact_depth: float, force_model: str = "fee",
                options=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Blade-frame (F_T, F_N) of each model term along the prediction (eq 1 split, ``contact_depth`` the
    surcharge ramp of the model options predicted with), and the carried load of the reference's fill (missing
    from the FEE); the payload models add their own carried load (``options``: the calibration's model options),
    ``"fee-learned"`` its learned correction."""
    soil, state, f = pred.soil, pred.state, pred.forces
    d = np.maximum(state.depth, 0.0)
    w = bucket.width
    tension = f.fee_force <= 0.0  # eq 1 clamped to 0: no term acts
    ramp = np.minimum(d / contact_depth, 1.0)
    fee_terms = {
        "gamma": d * d * w * soil.gamma * GRAVITY * f.n_gamma,
        "cohesion": soil.cohesion * w * d * f.n_c,
        "adhesion": soil.adhesion * w * d * f.n_a,
        "surcharge": ramp * state.load_weight(soil.gamma) * f.n_q,
    }
    out = {}
    for name, fee in fee_terms.items():
        fee = np.where(tension | (state.depth <= 0.0), 0.0, fee)
        out[name] = (fee * math.sin(soil.delta), fee * math.cos(soil.delta))
    zero = np.zeros_like(d)
    out["penetration"] = (w * bucket.edge_thickness * f.pressure * (state.depth > 0.0), zero)
    out["blade adhesion"] = (soil.adhesion * w * state.blade_length * (state.depth > 0.0), zero)
    weight = density * GRAVITY * np.asarray(state.fill_volume)
    a = np.asarray(pred.path.blade_angle)
    reference_fill = (weight * np.sin(a), weight * np.cos(a))
    if force_model == "fee":
        out["carried load (missing)"] = reference_fill
        return out
    from wheelloader.estimator.force_model import carried_forces

    out["carried load (model)"] = carried_forces(state.depth, state.blade_angle, state.carried_weight(soil.gamma),
                                                 state.acceleration, options)
    out["carried load (reference fill)"] = reference_fill
    if force_model == "fee-learned":
        from wheelloader.estimator.learned import default_learned_model, learned_forces

        lf = learned_forces(default_learned_model(), state, pred.path, bucket, soil)
        out["learned correction"] = (np.asarray(lf.tangential), np.asarray(lf.normal))
    return out


def _phase_entry(m, err_r, total_sq, scale, obs_r, pred_r, res_t, res_n, terms) -> dict:
    """One phase's share of the squared error, its RMSE, and the residual share each term's scaled copy removes."""
    n = int(np.count_nonzero(m))
    if n == 0:
        return {"samples": 0}
    r = np.concatenate([res_t[m], res_n[m]])
    rr = float(r @ r)
    shares = {}
    for term, (ft, fn) in terms.items():
        b = np.concatenate([ft[m], fn[m]])
        bb = float(b @ b)
        # a term numerically zero (a parameter fitted to ~1e-31) has no shape to book the error on
        shares[term] = 0.0 if bb <= 1e-18 * rr or rr <= 0.0 else float((r @ b) ** 2 / (bb * rr))
    return {
        "samples": n,
        "share_of_squared_error": float(np.sum(err_r[m] ** 2) / total_sq) if total_sq > 0 else 0.0,
        "rmse_percent_within_phase": 100.0 * float(np.sqrt(np.mean(err_r[m] ** 2))) / scale,
        "mean_observed_F_R": float(np.mean(obs_r[m])), "mean_predicted_F_R": float(np.mean(pred_r[m])),
        "mean_residual_F_T": float(np.mean(res_t[m])), "mean_residual_F_N": float(np.mean(res_n[m])),
        "residual_share_explained_by_term": shares,
        "mean_term_F_R": {t: float(np.mean(np.hypot(ft[m], fn[m]))) for t, (ft, fn) in terms.items()},
    }


def _rounded(values, digits: int = 1) -> list:
    return [round(float(v), digits) for v in np.asarray(values)[::SERIES_STRIDE]]


def analyse(train_name: str, test_name: str, data: Path, sigma: float, method: str, curl_rho: float,
            cache: dict, force_model: str = "fee") -> dict:
    """One (training cycle, predicted cycle) pair under one force model: the in-soil F_R error by phase and
    term, the error after exit, against the filtered and the unfiltered record; ``series`` for the figures."""
    from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
    from wheelloader.references import dem

    def load(name):
        raw = dem.load_reference(name, data)
        return raw, dem.filtered(raw, sigma)

    key = (train_name, force_model)
    if key not in cache:
        cache[key] = calibrate(load(train_name)[1], options=CalibrationOptions(method=method,
                                                                               force_model=force_model))
    cal = cache[key]
    raw, filt = load(test_name)
    pred = predict(cal, filt)
    pred_raw = predict(cal, raw)
    state = pred.state
    inside = state.depth > 0.0
    obs_r = filt.resultant
    scale = float(np.mean(np.abs(obs_r[inside])))
    err_r = pred.resultant - obs_r
    total_sq = float(np.sum(err_r[inside] ** 2))
    masks = phases_of(state, curl_rho)
    density = _reference_density(raw)
    terms = term_forces(pred, filt.bucket, density, cal.model_options.contact_depth, force_model,
                        cal.model_options)
    res_t = filt.tangential - pred.tangential
    res_n = filt.normal - pred.normal
    phases = {name: _phase_entry(m, err_r, total_sq, scale, obs_r, pred.resultant, res_t, res_n, terms)
              for name, m in masks.items()}
    out_of_soil = ~inside & (np.asarray(filt.fill_volume) > 0.0) if filt.fill_volume is not None else ~inside
    after: dict = {"samples": int(np.count_nonzero(out_of_soil))}
    if np.any(out_of_soil):
        for label, (obs, prd) in {"filtered": (obs_r, pred.resultant),
                                  "unfiltered": (raw.resultant, pred_raw.resultant)}.items():
            rmse = float(np.sqrt(np.mean((prd[out_of_soil] - obs[out_of_soil]) ** 2)))
            after[label] = [rmse, 100.0 * rmse / scale]
        after["mean_observed_F_R"] = float(np.mean(obs_r[out_of_soil]))
        after["mean_predicted_F_R"] = float(np.mean(pred.resultant[out_of_soil]))
        # the terms' part after exit: the model's carried load (and, for fee-learned, its correction)
        after["mean_term_F_R"] = {t: float(np.mean(np.hypot(ft[out_of_soil], fn[out_of_soil])))
                                  for t, (ft, fn) in terms.items() if t.startswith("carried") or t.startswith("learn")}
    outside = pred.outside_training
    reference_term = "carried load (missing)" if force_model == "fee" else "carried load (reference fill)"
    plotted = [t for t in ("gamma", "surcharge", "penetration", "carried load (model)", "learned correction")
               if t in terms]
    return {
        "train": train_name, "test": test_name, "method": method, "force_model": force_model,
        "rmse_percent": 100.0 * math.sqrt(total_sq / max(1, int(np.count_nonzero(inside)))) / scale,
        "rmse_percent_unfiltered": float(pred_raw.quality.percent_r) if pred_raw.quality else None,
        "params": cal.params.to_dict(), "reference_density": density,
        "phases": phases, "after_exit": after,
        "after_exit_mean_observed_F_R": after.get("mean_observed_F_R"),
        "after_exit_mean_carried_weight": (float(np.mean(np.hypot(*[c[out_of_soil] for c in terms[reference_term]])))
                                           if np.any(out_of_soil) else None),
        "outside_learned_range_in_soil": (float(np.mean(outside[inside])) if outside is not None and np.any(inside)
                                          else None),
        "series": {"t": _rounded(filt.path.t, 3), "obs_R": _rounded(obs_r),
                   "phase": [next((p for p, m in masks.items() if m[i]), "out")
                             for i in range(0, len(filt.path), SERIES_STRIDE)],
                   "pred_R": _rounded(pred.resultant),
                   "terms_R": {t: _rounded(np.hypot(*terms[t])) for t in plotted}},
    }


def analyse_case(train_name: str, test_name: str, label: str, data: Path, sigma: float, method: str,
                 curl_rho: float, cache: dict, force_models) -> dict:
    """:func:`analyse` for every force model; the shared series (time, reference, phases) kept once."""
    models = {}
    shared = None
    for name in force_models:
        entry = analyse(train_name, test_name, data, sigma, method, curl_rho, cache, name)
        series = entry.pop("series")
        shared = shared or {k: series[k] for k in ("t", "obs_R", "phase")}
        entry["series"] = {"pred_R": series["pred_R"], "terms_R": series["terms_R"]}
        models[name] = entry
    return {"train": train_name, "test": test_name, "label": label, "series": shared, "models": models}


def _reference_density(log) -> float:
    """The reference soil's bulk density [kg/m^3] from the log's metadata (MPM: the continuum's density)."""
    meta = log.metadata
    for key in ("bulk_density", "density"):
        if isinstance(meta.get(key), (int, float)):
            return float(meta[key])
    soil = meta.get("continuum") or {}
    if isinstance(soil, dict) and isinstance(soil.get("density"), (int, float)):
        return float(soil["density"])
    from wheelloader.references.mpm import ContinuumSoil

    return float(ContinuumSoil.from_soil(str(meta.get("soil"))).density)


def models_table(result: dict) -> list[str]:
    """Markdown lines: every force model per case, in soil and after exit, filtered / unfiltered (models.md)."""
    models = result["force_models"]
    lines = ["Each model calibrated (our method) on the training cycle and predicting the case. In soil: F_R RMSE "
             "in % of the mean observed |F_R| over the in-soil samples, against the filtered / unfiltered record. "
             "After exit: the samples with the tip above the surface and soil in the bucket (the reference's fill), "
             "RMSE in N and in % of the same in-soil mean, filtered / unfiltered.", "",
             "| case | " + " | ".join(f"{m} in soil" for m in models) + " | "
             + " | ".join(f"{m} after exit" for m in models) + " |",
             "|---|" + "---|" * (2 * len(models))]
    for case in result["cases"]:
        ms = case["models"]
        soil = [f"{ms[m]['rmse_percent']:.1f} / {ms[m]['rmse_percent_unfiltered']:.1f} %" for m in models]
        after = []
        for m in models:
            a = ms[m]["after_exit"]
            after.append(f"{a['filtered'][0]:.0f} N ({a['filtered'][1]:.0f} %) / {a['unfiltered'][1]:.0f} %"
                         if a.get("samples") else "-")
        lines.append(f"| {case['label']} | " + " | ".join(soil + after) + " |")
    if "fee-learned" in models:
        lines += ["", "`fee-learned`: share of the in-soil samples whose inputs leave the correction's trusted range "
                  "(flagged by the prediction; the correction is held at the range's edge there): "
                  + "; ".join(f"{c['label']} {100 * c['models']['fee-learned']['outside_learned_range_in_soil']:.0f} %"
                              for c in result["cases"]) + "."]
    return lines


def markdown(result: dict) -> str:
    models = result["force_models"]
    art = result.get("learned_artifact")
    lines = [f"# Error of the force models by phase and term ({result['data']}, method {result['method']})", "",
             f"`python benchmarks/error_analysis.py --data {result['data']} --force-models {' '.join(models)}` at "
             f"{commit_label(result['machine'])}; filter sigma {result['sigma_s']} s; "
             f"curl: rho < {result['curl_rho_deg']:g} deg.", ""]
    if art:
        lines += [f"`fee-learned` weights: `{art['path']}` version {art['version']}, SHA-256 `{art['sha256'][:16]}…`; "
                  f"its split: {art['split_rule']}.", ""]
    lines += ["## The models side by side", "", *models_table(result)]
    for m in models:
        terms = model_terms(m)
        lines += ["", f"## {m}: error by phase", "",
                  "Share of squared in-soil F_R error per phase (and the phase's own RMSE in % of the cycle's mean "
                  "|F_R|), and the term whose scaled copy removes most of that phase's residual (share of the "
                  "residual's sum of squares); after exit: mean measured / predicted F_R and the reference fill's "
                  "weight:", "",
                  "| case | F_R RMSE | " + " | ".join(PHASES) + " | after exit: measured / predicted F_R / carried "
                  "weight |", "|---|---|" + "---|" * len(PHASES) + "---|"]
        for case in result["cases"]:
            e = case["models"][m]
            cells = []
            for p in PHASES:
                ph = e["phases"][p]
                if not ph.get("samples"):
                    cells.append("-")
                    continue
                shares = ph["residual_share_explained_by_term"]
                best = max(shares, key=shares.get)
                cells.append(f"{100 * ph['share_of_squared_error']:.0f} % of error "
                             f"({ph['rmse_percent_within_phase']:.0f} %); {best} {100 * shares[best]:.0f} %")
            a = e["after_exit"]
            exit_cell = ("-" if not a.get("samples") else
                         f"{a['mean_observed_F_R']:.0f} / {a['mean_predicted_F_R']:.0f} / "
                         f"{e['after_exit_mean_carried_weight']:.0f} N")
            lines.append(f"| {case['label']} | {e['rmse_percent']:.1f} % | " + " | ".join(cells) + f" | {exit_cell} |")
        lines += ["", f"{m}: share of each phase's residual removed by a scaled copy of each term (%):", "",
                  "| case | phase | " + " | ".join(terms) + " |", "|---|---|" + "---|" * len(terms)]
        for case in result["cases"]:
            for p in PHASES:
                ph = case["models"][m]["phases"][p]
                if not ph.get("samples"):
                    continue
                s = ph["residual_share_explained_by_term"]
                lines.append(f"| {case['label']} | {p} | " + " | ".join(f"{100 * s[t]:.0f}" for t in terms) + " |")
    return "\n".join(lines) + "\n"


MODEL_COLOURS = {"fee": "C3", "fee-payload": "C0", "fee-learned": "C2"}


def figures(result: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"entry": "#fde0c5", "deep cut": "#d6e9f8", "curl": "#e2f0d9"}
    cases = result["cases"]
    models = result["force_models"]
    ncol = 3
    nrow = math.ceil(len(cases) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 3.6 * nrow), squeeze=False)
    for ax, case in zip(axes.ravel(), cases, strict=False):
        s = case["series"]
        t = np.array(s["t"])
        phase = np.array(s["phase"])
        for p, c in colours.items():
            m = phase == p
            if np.any(m):
                ax.axvspan(t[m].min(), t[m].max(), color=c, lw=0)
        ax.plot(t, s["obs_R"], "k", lw=1.4, label="reference F_R (filtered)")
        for name in models:
            e = case["models"][name]
            ax.plot(t, e["series"]["pred_R"], MODEL_COLOURS.get(name, "C5"), lw=1.2,
                    label=f"{name} F_R")
        terms = case["models"][models[-1]]["series"]["terms_R"]
        for term, style in (("carried load (model)", ":"), ("learned correction", "-.")):
            if term in terms:
                ax.plot(t, terms[term], MODEL_COLOURS.get(models[-1], "C5"), lw=0.8, ls=style,
                        label=f"{models[-1]}: {term}")
        ax.set(title=f"{case['label']}: " + ", ".join(f"{case['models'][m]['rmse_percent']:.1f}" for m in models)
               + " %", xlabel="t [s]", ylabel="force [N]")
        ax.title.set_fontsize(9)
    for ax in axes.ravel()[len(cases):]:
        ax.axis("off")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    handles += [plt.Rectangle((0, 0), 1, 1, color=c) for c in colours.values()]
    labels += [f"phase: {p}" for p in colours]
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(out / "phases.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(len(models), 1, figsize=(11, 3.6 * len(models)), squeeze=False)
    width = 0.8 / len(PHASES)
    x = np.arange(len(cases))
    for ax, name in zip(axes[:, 0], models, strict=True):
        for k, p in enumerate(PHASES):
            share = [100 * c["models"][name]["phases"][p].get("share_of_squared_error", 0.0) for c in cases]
            bars = ax.bar(x + (k - 1) * width, share, width, color=list(colours.values())[k], edgecolor="0.3",
                          label=p)
            for bar, c in zip(bars, cases, strict=True):
                ph = c["models"][name]["phases"][p]
                if ph.get("samples") and ph["share_of_squared_error"] > 0.08:
                    s = ph["residual_share_explained_by_term"]
                    best = max(s, key=s.get)
                    text = (f"{best.replace(' (missing)', '*')} {100 * s[best]:.0f} %" if s[best] >= 0.3
                            else "no single term")
                    ax.annotate(text, (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                                ha="center", va="bottom", fontsize=6.5, rotation=90, xytext=(0, 2),
                                textcoords="offset points")
        ax.set_xticks(x, [c["label"] for c in cases] if ax is axes[-1, 0] else [], rotation=25, ha="right",
                      fontsize=8)
        ax.set(ylabel="share of squared F_R error [%]", ylim=(0, 140),
               title=f"{name}: share of the in-soil error per phase, labelled with the term whose shape the "
                     "residual has (* = not in the model)")
        ax.title.set_fontsize(9)
        ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "terms.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="data/mpm", help="reference directory with manifest.json")
    parser.add_argument("--out", default="results/error_analysis", help="output directory")
    parser.add_argument("--sigma", type=float, default=0.1, help="Gaussian filter sigma of the reference [s]")
    parser.add_argument("--method", default="default", help="calibration method")
    parser.add_argument("--curl-rho", type=float, default=20.0, help="rho below which a sample is 'curl' [deg]")
    parser.add_argument("--force-models", nargs="+", default=list(FORCE_MODELS), metavar="NAME",
                        help=f"force models analysed side by side (default: all, {', '.join(FORCE_MODELS)})")
    args = parser.parse_args(argv)
    bad = [m for m in args.force_models if m not in FORCE_MODELS]
    if bad:
        print(f"wheelloader: error: unknown force model {bad[0]!r} (choose from {', '.join(FORCE_MODELS)})",
              file=sys.stderr)
        return 2
    if args.method != "default" and set(args.force_models) - {"fee"}:
        print("wheelloader: error: the payload models calibrate with the default method only", file=sys.stderr)
        return 2
    models = list(dict.fromkeys(args.force_models))
    data = Path(args.data)
    if not (data / "manifest.json").exists():
        print(f"wheelloader: error: no reference data in {data} (manifest.json missing)", file=sys.stderr)
        return 2
    names = {e["name"] for e in json.loads((data / "manifest.json").read_text())["cycles"]}
    cache: dict = {}
    cases = []
    for train, test, label in CASES:
        if {train, test} <= names:
            entry = analyse_case(train, test, label, data, args.sigma, args.method, math.radians(args.curl_rho),
                                 cache, models)
            cases.append(entry)
            print(f"{label}: " + ", ".join(f"{m} {e['rmse_percent']:.1f} %" for m, e in entry["models"].items()),
                  flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "error_analysis", "data": str(data), "method": args.method, "sigma_s": args.sigma,
              "curl_rho_deg": args.curl_rho, "force_models": models, "series_stride": SERIES_STRIDE,
              "learned_artifact": learned_artifact() if "fee-learned" in models else None,
              "machine": machine_info(), "cases": cases}
    (out / "error_analysis.json").write_text(json.dumps(result, indent=1))
    (out / "error_analysis.md").write_text(markdown(result))
    (out / "models.md").write_text("\n".join(models_table(result)) + "\n\n*`python benchmarks/error_analysis.py "
                                   f"--data {result['data']}` at {commit_label(result['machine'])}.*\n")
    figures(result, out)
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
