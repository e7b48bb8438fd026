"""What the free "lift" coefficient depends on across paths, and a lift term tied to gamma with no free coefficient
(issue #32, item 4: fit only what a cycle identifies, hold the rest at priors learned from the continuum).

``benchmarks/model_form.py``'s ``+ lift`` form (``F_T += a w g d^2 max(v_n, 0) / (|v| + v_0)``) lowers the floor
most, but its coefficient ``a`` is an 8th parameter fitted per path. Here:

1. **Dependence.** ``+ lift`` is fitted (model_form's grid + NNLS rule) to every cycle of ``transfer.py``'s
   TRAINING and VALIDATION splits (never the test set), and the ratio ``c = a / gamma`` (dimensionless) is set
   beside dimensionless features of the cycle's path: the maximum depth over the bucket's floor length
   ``d_max / L``, the blade angle to the horizontal at the deepest point, the lifting share (the in-soil mean of
   the lift column's rate factor), the kept fill at exit over the capacity and the mean in-soil speed as a Froude
   number ``v / sqrt(g L)``. Linear models of ``c`` on subsets of the features are fitted by least squares on the
   training cycles; the subset with the lowest validation RMSE of ``c`` is chosen (and the constant model is
   reported beside it).
2. **Tied lift.** The chosen ``c(features)`` (clipped at 0) ties the lift term to gamma: ``F_T += gamma c w g d^2
   max(v_n, 0) / (|v| + v_0)``, no coefficient of its own (as ``"fee-payload-depth"`` ties its wedge term). It is
   evaluated on ``data/mpm`` (the test set: reported, never used to choose) by model_form's protocol (one cycle,
   two cycles, floor; held-out soil and pile as their own rows), alone and on top of the N_gamma offset, and with
   phi and n held at the training cycles' medians of the tied form's own fits ("held prior"). model_form's
   ``fee-payload``, ``+ lift``, ``fee-payload-depth (k fixed)`` and ``fee-payload-depth + lift`` are run beside
   them with the same payload, so the rows compare forms.

Run: ``python benchmarks/lift_study.py --out docs/results/model_form/lift`` (about 10 CPU-minutes). Writes
``lift.json`` and ``lift.md``.
"""

from __future__ import annotations

import argparse
import importlib.util
import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np

from wheelloader.estimator import DEFAULT_PAYLOAD
from wheelloader.estimator.force_model import GRAVITY
from wheelloader.estimator.payload import PayloadOptions
from wheelloader.provenance import commit_label, machine_info

#: model_form's forms run beside the tied ones (free lift coefficient: an 8th parameter per path).
REFERENCE_FORMS = ("fee-payload", "+ lift", "fee-payload-depth (k fixed)", "fee-payload-depth + lift")
FEATURES = ("d_max/L", "blade angle at d_max", "lifting share", "kept fill", "Froude")


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"wheelloader_benchmark_{name}",
                                                  Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


mf = _module("model_form")


def features(case) -> np.ndarray:
    """The cycle's dimensionless path features (module docstring), in :data:`FEATURES` order."""
    st, i = case.state, case.idx
    length = case.bucket.floor_length
    k = int(np.argmax(case.d))
    vel = st.velocity[i]
    speed = float(np.mean(np.hypot(vel[:, 0], vel[:, 1])))
    kept = float(st.carried_volume[i][-1]) / case.bucket.capacity
    return np.array([float(case.d[k]) / length, float(st.blade_angle[i][k]), float(np.mean(case.lifting)), kept,
                     speed / math.sqrt(GRAVITY * length)])


class TiedLift:
    """``c(features) = max(b0 + b . x_S, 0)`` on the feature subset ``S`` (indices into :data:`FEATURES`)."""

    def __init__(self, subset: tuple[int, ...], coef: np.ndarray):
        self.subset, self.coef = tuple(subset), np.asarray(coef, dtype=float)

    def __call__(self, x: np.ndarray) -> float:
        return max(float(self.coef[0] + self.coef[1:] @ x[list(self.subset)]), 0.0)

    def to_dict(self) -> dict:
        return {"features": [FEATURES[j] for j in self.subset], "coefficients": self.coef.tolist()}


def fit_tie(x: np.ndarray, c: np.ndarray, subset: tuple[int, ...]) -> TiedLift:
    a = np.column_stack([np.ones(len(c)), x[:, list(subset)]])
    coef, *_ = np.linalg.lstsq(a, c, rcond=None)
    return TiedLift(subset, coef)


def tied_columns(tie: TiedLift, offset: bool):
    """model_form's ``columns`` with the tied lift in the gamma column of F_T (and the N_gamma offset if asked)."""
    base_terms = ("N_gamma offset",) if offset else ()

    def columns(case, phi, delta, n, terms):
        col_t, col_n = mf.columns(case, phi, delta, n, base_terms)
        c = tie(case.features)
        col_t = col_t.copy()
        col_t[:, 0] += c * case.bucket.width * GRAVITY * case.d ** 2 * case.lifting
        return col_t, col_n
    return columns


def fit_with(cols, cases, phi_grid, n_grid) -> dict:
    """model_form's grid + NNLS fit with another column builder and grids."""
    return mf.fit_form(cases, (), columns_of=cols, phi_grid=phi_grid, n_grid=n_grid)


def error_with(cols, case, fit) -> float:
    a_t, a_n = cols(case, fit["phi"], fit["delta"], fit["n"], ())
    x = np.asarray(fit["coefficients"])
    f_t, f_n = a_t @ x, a_n @ x
    return 100.0 * math.sqrt(float(np.mean((np.hypot(f_t, f_n) - case.obs_r) ** 2))) / case.scale


def load_cases(paths: list[str], payload: PayloadOptions) -> list:
    out = []
    for p in paths:
        try:
            case = mf.Case(Path(p), payload)
        except Exception as exc:  # a cycle without usable in-soil samples
            print(f"  {p} skipped ({exc})", flush=True)
            continue
        if case.idx.size < 10:
            continue
        case.features = features(case)
        case.path = p
        out.append(case)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/mpm"))
    parser.add_argument("--results", type=Path, default=Path("data/results"))
    parser.add_argument("--payload", type=Path, default=Path("docs/results/transfer/transfer.json"))
    parser.add_argument("--every", type=int, default=1, help="use every k-th training/validation cycle (profiling)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    payload = (PayloadOptions(**json.loads(args.payload.read_text())["payload"]) if args.payload.is_file()
               else DEFAULT_PAYLOAD)
    split = _module("transfer").split(args.data, args.results)
    groups = {}
    for part in ("train", "validation"):
        cases = load_cases(split[part][::args.every], payload)
        rows = []
        for case in cases:
            fit = mf.fit_form([case], ("lift",))
            gamma, a = fit["coefficients"][0], fit["coefficients"][4]
            rows.append({"cycle": case.path, "features": case.features.tolist(), "gamma": gamma, "lift": a,
                         "c": a / gamma if gamma > 0 else 0.0, "phi_deg": math.degrees(fit["phi"]), "n": fit["n"]})
            print(f"{part} {case.path}: c {rows[-1]['c']:.2f} x {np.round(case.features, 2)}", flush=True)
        groups[part] = rows
    xt = np.array([r["features"] for r in groups["train"]])
    ct = np.array([r["c"] for r in groups["train"]])
    xv = np.array([r["features"] for r in groups["validation"]])
    cv = np.array([r["c"] for r in groups["validation"]])
    corr = {FEATURES[j]: float(np.corrcoef(xt[:, j], ct)[0, 1]) for j in range(len(FEATURES))}
    candidates = []
    for size in range(0, 3):
        for subset in itertools.combinations(range(len(FEATURES)), size):
            tie = fit_tie(xt, ct, subset)
            pred = np.array([tie(x) for x in xv])
            candidates.append({"tie": tie, "validation_rmse": float(np.sqrt(np.mean((pred - cv) ** 2))),
                               "train_rmse": float(np.sqrt(np.mean((np.array([tie(x) for x in xt]) - ct) ** 2)))})
    candidates.sort(key=lambda r: r["validation_rmse"])
    chosen = candidates[0]["tie"]
    constant = next(r["tie"] for r in candidates if not r["tie"].subset)
    print(f"chosen tie {chosen.to_dict()}; constant {constant.to_dict()}", flush=True)

    files = {soil: [args.data / f"{soil}_path{i}.csv" for i in range(1, 5)] for soil in mf.SOILS}
    files["gravel_slope25"] = [args.data / "gravel_slope25_path1.csv"]
    test = {k: load_cases([str(f) for f in fs], payload) for k, fs in files.items()}
    forms = {}
    for label in REFERENCE_FORMS:  # model_form's forms with this run's payload, for the side-by-side
        terms = mf.FORMS[label]
        records = mf.protocol(test, lambda group, terms=terms: mf.fit_form(group, terms),
                              lambda case, f, terms=terms: mf.form_error(case, f, terms)[0])
        forms[label] = {"terms": list(terms), "records": records, "summary": mf.summary(records)}
        s = forms[label]["summary"]["all unseen"]
        print(f"form {label}: one {s['one cycle']:.1f}, two {s['two cycles']:.1f}, floor {s['floor']:.1f}",
              flush=True)
    train_cases = None
    for label, tie, offset, held in (("fee-payload + lift tied (constant c)", constant, False, False),
                                     ("fee-payload + lift tied (c of features)", chosen, False, False),
                                     ("fee-payload-depth + lift tied (c of features)", chosen, True, False),
                                     ("fee-payload + lift tied (c of features), held phi, n", chosen, False, True)):
        cols = tied_columns(tie, offset)
        phi_grid, n_grid, prior = mf.PHI_GRID, mf.N_GRID, None
        if held:  # phi and n at the training cycles' medians of this form's own fits
            if train_cases is None:
                train_cases = load_cases(split["train"][::max(args.every, 4)], payload)
            own = [fit_with(cols, [c], mf.PHI_GRID, mf.N_GRID) for c in train_cases]
            phi0 = float(np.median([f["phi"] for f in own]))
            n0 = float(min(mf.N_GRID, key=lambda v: abs(v - np.median([f["n"] for f in own]))))
            phi0 = float(mf.PHI_GRID[np.argmin(np.abs(mf.PHI_GRID - phi0))])
            phi_grid, n_grid, prior = np.array([phi0]), (n0,), {"phi_deg": math.degrees(phi0), "n": n0}
        records = mf.protocol(test, lambda group, cols=cols, pg=phi_grid, ng=n_grid: fit_with(cols, group, pg, ng),
                              lambda case, f, cols=cols: error_with(cols, case, f))
        forms[label] = {"tie": tie.to_dict(), "offset": offset, "held_prior": prior, "records": records,
                        "summary": mf.summary(records)}
        s = forms[label]["summary"]["all unseen"]
        print(f"form {label}: one {s['one cycle']:.1f}, two {s['two cycles']:.1f}, floor {s['floor']:.1f}",
              flush=True)
    result = {"benchmark": "lift_study", "payload": payload.to_dict(), "features": list(FEATURES),
              "correlation_with_c_train": corr, "cycles": groups,
              "ties": [{**r["tie"].to_dict(), "validation_rmse": r["validation_rmse"], "train_rmse": r["train_rmse"]}
                       for r in candidates],
              "chosen": chosen.to_dict(), "forms": forms, "machine": machine_info()}
    result["revision"] = commit_label(result["machine"])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "lift.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "lift.md").write_text(table(result))
    print(table(result), end="")
    return 0


def table(result: dict) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.1f}"  # noqa: E731
    c = np.array([r["c"] for r in result["cycles"]["train"]])
    lines = [f"Training cycles: {len(c)}; c = a / gamma median {np.median(c):.2f}, 10-90 % "
             f"{np.percentile(c, 10):.2f}-{np.percentile(c, 90):.2f}; correlation with c (train): "
             + ", ".join(f"{k} {v:+.2f}" for k, v in result["correlation_with_c_train"].items()) + ".", "",
             "| tie of c | validation RMSE of c | train RMSE of c |", "|---|---|---|"]
    for r in result["ties"][:6]:
        lines.append(f"| {r['features'] or 'constant'}: {np.round(r['coefficients'], 3).tolist()} | "
                     f"{r['validation_rmse']:.2f} | {r['train_rmse']:.2f} |")
    lines += ["", "| row | form | one cycle | two cycles | floor |", "|---|---|---|---|---|"]
    for row in ("all unseen", *mf.ROWS.values()):
        for form, res in result["forms"].items():
            s = res["summary"][row]
            lines.append(f"| {row} | {form} | {fmt(s['one cycle'])} % | {fmt(s['two cycles'])} % | "
                         f"{fmt(s['floor'])} % |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
