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

Run: ``python benchmarks/error_analysis.py --data data/mpm --out docs/results/error_mpm``.
Writes ``error_analysis.json``, ``error_analysis.md``, ``phases.png`` and ``terms.png``.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from wheelloader.estimator import GRAVITY
from wheelloader.provenance import commit_label, machine_info

PHASES = ("entry", "deep cut", "curl")
TERMS = ("gamma", "cohesion", "adhesion", "surcharge", "penetration", "blade adhesion", "carried load (missing)")
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


def term_forces(pred, bucket, density: float, contact_depth: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Blade-frame (F_T, F_N) of each model term along the prediction (eq 1 split, ``contact_depth`` the
    surcharge ramp of the model options predicted with), and the missing carried load."""
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
    out["carried load (missing)"] = (weight * np.sin(a), weight * np.cos(a))
    return out


def analyse(train_name: str, test_name: str, data: Path, sigma: float, method: str, curl_rho: float,
            cache: dict) -> dict:
    from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
    from wheelloader.references import dem

    def load(name):
        raw = dem.load_reference(name, data)
        return raw, dem.filtered(raw, sigma)

    if train_name not in cache:
        cache[train_name] = calibrate(load(train_name)[1], options=CalibrationOptions(method=method))
    cal = cache[train_name]
    raw, filt = load(test_name)
    pred = predict(cal, filt)
    state = pred.state
    inside = state.depth > 0.0
    obs_r = filt.resultant
    scale = float(np.mean(np.abs(obs_r[inside])))
    err_r = pred.resultant - obs_r
    total_sq = float(np.sum(err_r[inside] ** 2))
    masks = phases_of(state, curl_rho)
    density = _reference_density(raw)
    terms = term_forces(pred, filt.bucket, density, cal.model_options.contact_depth)
    res_t = filt.tangential - pred.tangential
    res_n = filt.normal - pred.normal
    phases = {}
    for name, m in masks.items():
        n = int(np.count_nonzero(m))
        if n == 0:
            phases[name] = {"samples": 0}
            continue
        r = np.concatenate([res_t[m], res_n[m]])
        rr = float(r @ r)
        shares = {}
        for term, (ft, fn) in terms.items():
            b = np.concatenate([ft[m], fn[m]])
            bb = float(b @ b)
            shares[term] = 0.0 if bb <= 0.0 or rr <= 0.0 else float((r @ b) ** 2 / (bb * rr))
        phases[name] = {
            "samples": n,
            "share_of_squared_error": float(np.sum(err_r[m] ** 2) / total_sq) if total_sq > 0 else 0.0,
            "rmse_percent_within_phase": 100.0 * float(np.sqrt(np.mean(err_r[m] ** 2))) / scale,
            "mean_observed_F_R": float(np.mean(obs_r[m])), "mean_predicted_F_R": float(np.mean(pred.resultant[m])),
            "mean_residual_F_T": float(np.mean(res_t[m])), "mean_residual_F_N": float(np.mean(res_n[m])),
            "residual_share_explained_by_term": shares,
            "mean_term_F_R": {t: float(np.mean(np.hypot(ft[m], fn[m]))) for t, (ft, fn) in terms.items()},
        }
    out_of_soil = ~inside & (np.asarray(filt.fill_volume) > 0.0) if filt.fill_volume is not None else ~inside
    return {
        "train": train_name, "test": test_name, "method": method,
        "rmse_percent": 100.0 * math.sqrt(total_sq / max(1, int(np.count_nonzero(inside)))) / scale,
        "params": cal.params.to_dict(), "reference_density": density,
        "phases": phases,
        "after_exit_mean_observed_F_R": float(np.mean(obs_r[out_of_soil])) if np.any(out_of_soil) else None,
        "after_exit_mean_carried_weight": (float(np.mean(np.hypot(*[c[out_of_soil] for c in
                                                                   terms["carried load (missing)"]])))
                                           if np.any(out_of_soil) else None),
        "series": {"t": filt.path.t.tolist(), "obs_T": filt.tangential.tolist(), "obs_N": filt.normal.tolist(),
                   "pred_T": pred.tangential.tolist(), "pred_N": pred.normal.tolist(),
                   "phase": [next((p for p, m in masks.items() if m[i]), "out") for i in range(len(filt.path))],
                   "terms_R": {t: np.hypot(ft, fn).tolist() for t, (ft, fn) in terms.items()}},
    }


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


def markdown(result: dict) -> str:
    lines = [f"# Error of the force model by phase and term ({result['data']}, method {result['method']})", "",
             f"{commit_label(result['machine'])}; filter sigma {result['sigma_s']} s; "
             f"curl: rho < {result['curl_rho_deg']:g} deg.", "",
             "Share of squared F_R error per phase (and the phase's own RMSE in % of the cycle's mean |F_R|), "
             "and the term whose scaled copy removes most of that phase's residual (share of the residual's "
             "sum of squares):", "",
             "| case | F_R RMSE | " + " | ".join(PHASES) + " | after exit: measured F_R / carried weight |",
             "|---|---|" + "---|" * len(PHASES) + "---|"]
    for case in result["cases"]:
        cells = []
        for p in PHASES:
            ph = case["phases"][p]
            if not ph.get("samples"):
                cells.append("-")
                continue
            shares = ph["residual_share_explained_by_term"]
            best = max(shares, key=shares.get)
            cells.append(f"{100 * ph['share_of_squared_error']:.0f} % of error "
                         f"({ph['rmse_percent_within_phase']:.0f} %); {best} {100 * shares[best]:.0f} %")
        exit_cell = ("-" if case["after_exit_mean_observed_F_R"] is None else
                     f"{case['after_exit_mean_observed_F_R']:.0f} / {case['after_exit_mean_carried_weight']:.0f} N")
        lines.append(f"| {case['label']} | {case['rmse_percent']:.1f} % | " + " | ".join(cells) + f" | {exit_cell} |")
    lines += ["", "Share of each phase's residual removed by a scaled copy of each term (%):", "",
              "| case | phase | " + " | ".join(TERMS) + " |", "|---|---|" + "---|" * len(TERMS)]
    for case in result["cases"]:
        for p in PHASES:
            ph = case["phases"][p]
            if not ph.get("samples"):
                continue
            s = ph["residual_share_explained_by_term"]
            lines.append(f"| {case['label']} | {p} | " + " | ".join(f"{100 * s[t]:.0f}" for t in TERMS) + " |")
    return "\n".join(lines) + "\n"


def figures(result: dict, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"entry": "#fde0c5", "deep cut": "#d6e9f8", "curl": "#e2f0d9"}
    cases = result["cases"]
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
        obs = np.hypot(s["obs_T"], s["obs_N"])
        pred = np.hypot(s["pred_T"], s["pred_N"])
        ax.plot(t, obs, "k", lw=1.4, label="reference F_R (filtered)")
        ax.plot(t, pred, "C3", lw=1.4, label="model F_R")
        ax.plot(t, s["terms_R"]["gamma"], "C0", lw=0.8, ls="--", label="gamma term")
        ax.plot(t, s["terms_R"]["surcharge"], "C2", lw=0.8, ls="--", label="surcharge term")
        ax.plot(t, s["terms_R"]["penetration"], "C4", lw=0.8, ls="--", label="penetration term")
        ax.plot(t, s["terms_R"]["carried load (missing)"], "C1", lw=0.8, ls=":", label="carried load (not in model)")
        ax.set(title=f"{case['label']}: {case['rmse_percent']:.1f} %", xlabel="t [s]", ylabel="force [N]")
        ax.title.set_fontsize(9)
    for ax in axes.ravel()[len(cases):]:
        ax.axis("off")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    handles += [plt.Rectangle((0, 0), 1, 1, color=c) for c in colours.values()]
    labels += [f"phase: {p}" for p in colours]
    fig.legend(handles, labels, loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(out / "phases.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(11, 4.8))
    width = 0.8 / len(PHASES)
    x = np.arange(len(cases))
    for k, p in enumerate(PHASES):
        share = [100 * c["phases"][p].get("share_of_squared_error", 0.0) for c in cases]
        bars = ax.bar(x + (k - 1) * width, share, width, color=list(colours.values())[k], edgecolor="0.3", label=p)
        for bar, c in zip(bars, cases, strict=True):
            ph = c["phases"][p]
            if ph.get("samples") and ph["share_of_squared_error"] > 0.08:
                s = ph["residual_share_explained_by_term"]
                best = max(s, key=s.get)
                text = (f"{best.replace(' (missing)', '*')} {100 * s[best]:.0f} %" if s[best] >= 0.3
                        else "no single term")
                ax.annotate(text, (bar.get_x() + bar.get_width() / 2, bar.get_height()),
                            ha="center", va="bottom", fontsize=6.5, rotation=90, xytext=(0, 2),
                            textcoords="offset points")
    ax.set_xticks(x, [c["label"] for c in cases], rotation=25, ha="right", fontsize=8)
    ax.set(ylabel="share of squared F_R error [%]", ylim=(0, 140),
           title="Where the error is: share per phase, labelled with the term whose shape the residual has "
                 "(* = not in the model)")
    ax.title.set_fontsize(9)
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "terms.png", dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", default="data/mpm", help="reference directory with manifest.json")
    parser.add_argument("--out", default="results/error_analysis", help="output directory")
    parser.add_argument("--sigma", type=float, default=0.1, help="Gaussian filter sigma of the reference [s]")
    parser.add_argument("--method", default="default", help="calibration method")
    parser.add_argument("--curl-rho", type=float, default=20.0, help="rho below which a sample is 'curl' [deg]")
    args = parser.parse_args(argv)
    data = Path(args.data)
    names = {e["name"] for e in json.loads((data / "manifest.json").read_text())["cycles"]}
    cache: dict = {}
    cases = []
    for train, test, label in CASES:
        if {train, test} <= names:
            entry = analyse(train, test, data, args.sigma, args.method, math.radians(args.curl_rho), cache)
            entry["label"] = label
            cases.append(entry)
            print(f"{label}: {entry['rmse_percent']:.1f} %", flush=True)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = {"benchmark": "error_analysis", "data": str(data), "method": args.method, "sigma_s": args.sigma,
              "curl_rho_deg": args.curl_rho, "machine": machine_info(), "cases": cases}
    (out / "error_analysis.json").write_text(json.dumps(result, indent=1))
    (out / "error_analysis.md").write_text(markdown(result))
    figures(result, out)
    print(markdown(result))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
