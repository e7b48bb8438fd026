"""Where the payload model's floor lives, and which physical terms would lower it (issue #32).

Test data: ``data/mpm``'s four smooth paths per soil (gravel, sand, modified sand, dirt) and the 25 deg pile
(``gravel_slope25_path1``), Gaussian-filtered at sigma 0.1 s, the split of ``benchmarks/transfer.py``. Nothing
here is trained on other data except the payload ``(r, h, p)``, which is the one ``transfer.py`` fitted to its
training loops (read from ``--payload``, else :data:`~wheelloader.estimator.DEFAULT_PAYLOAD`).

**Part 1, phases.** Each path is calibrated on itself (the floor; ``calibrate``, varpro, the paper's bounds) with
``"fee"``, ``"fee-payload"`` and ``"fee-payload-depth"``, and the in-soil F_R error is booked by phase with
``error_analysis.py``'s rule (``entry``: before 90 % of the maximum depth; ``deep cut``: after it while rho >= 20
deg; ``curl``: rho below 20 deg); beside it the error *after exit* (tip out of the soil, load in the bucket; not in
the floor, % of the same in-soil mean), the share of the in-soil squared error in F_T and in F_N, and the mean
signed F_T residual (observed - model) of each phase in % of the in-soil mean |F_R| (negative: the model is too high
there).

**Part 2, forms.** Candidate terms beyond the FEE, each with its own free non-negative coefficient, added to the
``"fee-payload"`` form and fitted by the same rule for every form: a grid over (phi, delta, n) (phi 5-45 deg,
delta 5-40 deg by 2.5 deg, n in {0.5, 1, 1.53}: the paper's bound on n), at each grid point non-negative least
squares of the stacked [F_T; F_N] in-soil residual (eq 19a, lambda 0.5) for the linear coefficients
(gamma, C, C_a, K and the term's), the grid point with the lowest cost kept. gamma is not bounded here (the paper's
1297 kg/m^3 lower bound is what pushes ``calibrate``'s phi 15-30 deg below the continuum's); the form ``fee-payload``
in this table is the same fit without an extra term, so the rows compare forms, not fitters. Reported like
``transfer.py``: the median over unseen paths of F_R RMSE in soil from ONE cycle (each path predicts the other
three of its soil; the gravel paths also the 25 deg pile), from TWO (neighbouring paths predict the other two),
and the floor (each path fitted to itself), per row (soil, held-out soil, held-out pile).

The terms (``g`` gravity, ``w`` width, ``d`` depth, ``v`` the tip velocity, ``v_a`` its component along the blade,
``v_n`` along the blade's normal, ``v_0`` 0.05 m/s, ``s_a = (max(v_a, 0) + v_0) / (|v| + v_0)`` the share of the
motion that advances the edge, :func:`~wheelloader.estimator.force_model.slip_factor`):

* ``edge``: resistance of the edge while it advances into the soil, ``F_T += a w g d^2 s_a``;
* ``lift``: drag of the soil on the floor while the bucket moves along its normal,
  ``F_T += a w g d^2 max(v_n, 0) / (|v| + v_0)``;
* ``push``: the carved soil heaped in the bucket pushed along while the edge advances (its weight times a
  friction), ``F_T += a g V_carved s_a``;
* ``kept weight``: the kept soil's weight in soil with its own coefficient (blade frame);
* ``wedge``: a depth-squared term with its own coefficient in both components, ``a w g d^2`` (depth scaling the
  calibrated phi need not absorb);
* ``gated Bekker``: the penetration term only while the edge advances, ``K w b d^n s_a`` (no new coefficient);
* ``fee-payload-depth (k fixed)``: the shipped ``"fee-payload-depth"`` form, N_gamma + k with k fixed at
  :data:`~wheelloader.estimator.DEFAULT_WEDGE_OFFSET` (the ``wedge`` term along the FEE's direction, tied to gamma:
  no coefficient of its own); ``fee-payload-depth + lift`` and ``+ edge + lift``: that form with the free terms
  (what a parameter of its own for them would add to the shipped form).

``--fit-offset`` fits that k instead (:func:`fit_offset`, the training loops only) and writes ``offset.json``.

Run: ``python benchmarks/model_form.py --out docs/results/model_form`` (about 6 CPU-minutes). Writes
``model_form.json``, ``phases.md``, ``forms.md`` and ``model_form.png``.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.optimize import nnls

from wheelloader.estimator import DEFAULT_PAYLOAD, DEFAULT_WEDGE_OFFSET, CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.calibration.fit_factors import factors
from wheelloader.estimator.force_model import GRAVITY, ModelOptions, carried_load_factors, slip_factor
from wheelloader.estimator.payload import PayloadOptions, payload_contact_state
from wheelloader.provenance import commit_label, machine_info
from wheelloader.references.filtering import filtered

SOILS = ("gravel", "sand", "modified_sand", "dirt")
ROWS = {"gravel": "gravel", "sand": "sand", "modified_sand": "modified sand (unseen soil)",
        "dirt": "dirt (held-out soil)", "gravel_slope25": "25 deg pile (held-out pile)"}
SIGMA = 0.1
CURL_RHO = math.radians(20.0)
PHASES = ("entry", "deep cut", "curl")
PHI_GRID = np.radians(np.arange(5.0, 45.01, 2.5))
DELTA_GRID = np.radians(np.arange(5.0, 40.01, 2.5))
N_GRID = (0.5, 1.0, 1.53)
SLIP_SPEED = 0.05
#: The forms of part 2: the extra terms each adds to the fee-payload form.
FORMS: dict[str, tuple[str, ...]] = {
    "fee-payload": (), "+ gated Bekker": ("gated Bekker",), "+ wedge": ("wedge",), "+ kept weight": ("kept weight",),
    "+ push": ("push",), "+ edge": ("edge",), "+ lift": ("lift",), "+ edge + lift": ("edge", "lift"),
    "+ push + lift": ("push", "lift"), "+ edge + push + lift": ("edge", "push", "lift"),
    "fee-payload-depth (k fixed)": ("N_gamma offset",), "fee-payload-depth + lift": ("N_gamma offset", "lift"),
    "fee-payload-depth + edge + lift": ("N_gamma offset", "edge", "lift"),
}


def _error_analysis():
    """``benchmarks/error_analysis.py`` as a module (its phase rule is the one reused here)."""
    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_error_analysis",
                                                  Path(__file__).with_name("error_analysis.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class Case:
    """One test cycle: raw and filtered log, its payload contact state and the in-soil geometry the fits use."""

    def __init__(self, path: Path, payload: PayloadOptions):
        self.name = path.stem
        self.raw = CycleLog.load(path)
        self.filt = filtered(self.raw, SIGMA)
        self.state = payload_contact_state(self.filt, payload)
        st = self.state
        self.idx = np.flatnonzero(st.depth > 0.0)
        i = self.idx
        self.d = st.depth[i]
        self.y_t, self.y_n = self.filt.tangential[i], self.filt.normal[i]
        self.obs_r = np.hypot(self.y_t, self.y_n)
        self.scale = float(np.mean(self.obs_r))
        self.bucket = self.raw.bucket
        th = st.blade_angle[i]
        vel = st.velocity[i]
        speed = np.hypot(vel[:, 0], vel[:, 1])
        self.advance = slip_factor(th, vel, SLIP_SPEED)
        self.lifting = np.maximum(-vel[:, 0] * np.sin(th) + vel[:, 1] * np.cos(th), 0.0) / (speed + SLIP_SPEED)
        self.carried = carried_load_factors(th)
        self.hand_over = 1.0 - np.minimum(self.d / ModelOptions().contact_depth, 1.0)


def extra_columns(case: Case, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The (F_T, F_N) column of one candidate term per unit coefficient (module docstring)."""
    w, d, zero = case.bucket.width, case.d, np.zeros_like(case.d)
    kept = case.state.carried_volume[case.idx]
    carved = case.state.fill_volume[case.idx]
    if name == "edge":
        return w * GRAVITY * d * d * case.advance, zero
    if name == "lift":
        return w * GRAVITY * d * d * case.lifting, zero
    if name == "push":
        return GRAVITY * carved * case.advance, zero
    if name == "kept weight":
        return GRAVITY * kept * case.carried[0], GRAVITY * kept * case.carried[1]
    if name == "wedge":
        return w * GRAVITY * d * d, w * GRAVITY * d * d
    raise ValueError(name)


def columns(case: Case, phi: float, delta: float, n: float, terms: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Design matrices (samples x coefficients) of F_T and F_N: gamma, C, C_a, K, then the terms' coefficients."""
    st, i, w, d = case.state, case.idx, case.bucket.width, case.d
    fac = factors(st.alpha[i], st.rho[i], phi, delta, ModelOptions())
    ramp = 1.0 - case.hand_over
    b_gamma = d * d * w * GRAVITY * np.maximum(fac.n_gamma, 0.0) + ramp * GRAVITY * st.fill_volume[i] * fac.n_q  # eq 1
    b_c, b_a = w * d * fac.n_c, w * d * fac.n_a
    kept = GRAVITY * st.carried_volume[i] * case.hand_over  # fee-payload's carried load, handed over at exit
    sd, cd = math.sin(delta), math.cos(delta)
    sink = w * case.bucket.edge_thickness * d ** n  # eq 15
    if "gated Bekker" in terms:
        sink = sink * case.advance
    if "N_gamma offset" in terms:  # fee-payload-depth: N_gamma + k, k fixed (no coefficient of its own)
        b_gamma = b_gamma + DEFAULT_WEDGE_OFFSET * d * d * w * GRAVITY
    col_t = [sd * b_gamma + kept * case.carried[0], sd * b_c, sd * b_a + w * st.blade_length[i], sink]  # eq 16
    col_n = [cd * b_gamma + kept * case.carried[1], cd * b_c, cd * b_a, np.zeros_like(d)]  # eq 17
    for name in terms:
        if name not in ("gated Bekker", "N_gamma offset"):
            ct, cn = extra_columns(case, name)
            col_t.append(ct)
            col_n.append(cn)
    return np.column_stack(col_t), np.column_stack(col_n)


def fit_form(cases: list[Case], terms: tuple[str, ...], columns_of: Callable | None = None, phi_grid=None,
             n_grid=None) -> dict:
    """The grid + non-negative least-squares fit of one form to one or several cycles (module docstring).

    ``columns_of`` (default :func:`columns`) builds a cycle's columns, ``phi_grid`` and ``n_grid`` (default
    :data:`PHI_GRID`, :data:`N_GRID`) are the grids searched (``benchmarks/lift_study.py`` passes its own).
    """
    columns_of = columns if columns_of is None else columns_of
    best = {"cost": math.inf}
    y = np.concatenate([np.concatenate([c.y_t, c.y_n]) for c in cases])
    for phi in PHI_GRID if phi_grid is None else phi_grid:
        for delta in DELTA_GRID:
            for n in N_GRID if n_grid is None else n_grid:
                mats = [columns_of(c, phi, delta, n, terms) for c in cases]
                a = np.vstack([np.vstack(m) for m in mats])
                norm = np.linalg.norm(a, axis=0) + 1e-30
                x, res = nnls(a / norm, y)
                if res < best["cost"]:
                    best = {"cost": float(res), "phi": float(phi), "delta": float(delta), "n": float(n),
                            "coefficients": (x / norm).tolist()}
    return best


def form_error(case: Case, fit: dict, terms: tuple[str, ...]) -> tuple[float, np.ndarray, np.ndarray]:
    """F_R RMSE in soil [% of the mean observed |F_R|] of a fitted form on ``case``, and its (F_T, F_N)."""
    a_t, a_n = columns(case, fit["phi"], fit["delta"], fit["n"], terms)
    x = np.asarray(fit["coefficients"])
    f_t, f_n = a_t @ x, a_n @ x
    return 100.0 * math.sqrt(float(np.mean((np.hypot(f_t, f_n) - case.obs_r) ** 2))) / case.scale, f_t, f_n


def protocol(cases: dict[str, list[Case]], fit: Callable[[list[Case]], object],
             error: Callable[[Case, object], float]) -> list[dict]:
    """``transfer.py``'s predictions: floor, one cycle, two cycles, per soil; the gravel fits also predict the pile."""
    records = []
    slope = cases["gravel_slope25"][0]
    for soil in SOILS:
        paths = cases[soil]
        fits = [fit([p]) for p in paths]
        for i, p in enumerate(paths):
            records.append({"row": ROWS[soil], "mode": "floor", "test": p.name, "error": error(p, fits[i])})
            for j, q in enumerate(paths):
                if j != i:
                    records.append({"row": ROWS[soil], "mode": "one cycle", "test": q.name, "train": p.name,
                                    "error": error(q, fits[i])})
            if soil == "gravel":
                records.append({"row": ROWS["gravel_slope25"], "mode": "one cycle", "test": slope.name,
                                "train": p.name, "error": error(slope, fits[i])})
        for i in range(len(paths) - 1):
            pair = fit(paths[i:i + 2])
            others = [q for j, q in enumerate(paths) if j not in (i, i + 1)]
            for q in others:
                records.append({"row": ROWS[soil], "mode": "two cycles", "test": q.name,
                                "train": f"{paths[i].name}+{paths[i + 1].name}", "error": error(q, pair)})
            if soil == "gravel":
                records.append({"row": ROWS["gravel_slope25"], "mode": "two cycles", "test": slope.name,
                                "train": f"{paths[i].name}+{paths[i + 1].name}", "error": error(slope, pair)})
    records.append({"row": ROWS["gravel_slope25"], "mode": "floor", "test": slope.name,
                    "error": error(slope, fit([slope]))})
    return records


def summary(records: list[dict]) -> dict:
    """Median error per row and mode (and over all unseen paths)."""
    out = {}
    for row in ("all unseen", *ROWS.values()):
        out[row] = {}
        for mode in ("one cycle", "two cycles", "floor"):
            vals = [r["error"] for r in records if r["mode"] == mode and (row == "all unseen" or r["row"] == row)]
            out[row][mode] = float(np.median(vals)) if vals else None
    return out


def phase_study(cases: dict[str, list[Case]], payload: PayloadOptions, phases_of) -> dict:
    """Part 1 (module docstring): the floor of ``fee`` and ``fee-payload``, booked by phase."""
    out = {}
    for model in ("fee", "fee-payload", "fee-payload-depth"):
        options = (CalibrationOptions(fill="model") if model == "fee"
                   else CalibrationOptions(force_model=model, payload=payload))
        rows = []
        for case in [c for soil in (*SOILS, "gravel_slope25") for c in cases[soil]]:
            cal = calibrate(case.filt, options=options)
            pred = predict(cal, case.filt)
            st, filt = pred.state, case.filt
            inside = st.depth > 0.0
            obs_r = np.hypot(filt.tangential, filt.normal)
            scale = float(np.mean(obs_r[inside]))
            pred_r = np.hypot(pred.tangential, pred.normal)
            err = pred_r - obs_r
            total = float(np.sum(err[inside] ** 2))
            res_t = filt.tangential - pred.tangential
            res_n = filt.normal - pred.normal
            masks = phases_of(st, CURL_RHO)
            first = int(np.flatnonzero(inside)[0])
            after = ~inside & (np.arange(inside.size) > first) & (np.asarray(case.raw.fill_volume) > 0.0)
            row = {"case": case.name, "floor": 100.0 * math.sqrt(total / int(inside.sum())) / scale,
                   "share_F_T": 100.0 * float(np.sum(res_t[inside] ** 2))
                   / float(np.sum(res_t[inside] ** 2) + np.sum(res_n[inside] ** 2)),
                   "max_depth_over_L": float(np.max(st.depth)) / case.bucket.floor_length,
                   "params": {"phi_deg": math.degrees(cal.params.phi), "delta_deg": math.degrees(cal.params.delta),
                              "gamma": cal.params.gamma, "n": cal.params.n, "cohesion": cal.params.cohesion},
                   "phases": {}}
            for name, m in masks.items():
                row["phases"][name] = {
                    "share": 100.0 * float(np.sum(err[m] ** 2)) / total if total > 0 else 0.0,
                    "rmse": 100.0 * math.sqrt(float(np.mean(err[m] ** 2))) / scale if m.any() else None,
                    "mean_residual_T": 100.0 * float(np.mean(res_t[m])) / scale if m.any() else None,
                    "mean_residual_N": 100.0 * float(np.mean(res_n[m])) / scale if m.any() else None}
            row["after_exit"] = (100.0 * math.sqrt(float(np.mean(err[after] ** 2))) / scale if after.any() else None)
            rows.append(row)
            print(f"phases {model} {case.name}: floor {row['floor']:.1f} %", flush=True)
        out[model] = rows
    return out


def phases_table(result: dict) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.0f}"  # noqa: E731
    lines = ["| model | case | floor | max depth / L | F_T share of the squared error | entry: share, RMSE, mean F_T "
             "residual | deep cut | curl | after exit (RMSE) | fitted phi, n |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for model, rows in result["phases"].items():
        for r in rows:
            cells = []
            for p in PHASES:
                ph = r["phases"][p]
                cells.append(f"{fmt(ph['share'])} %, {fmt(ph['rmse'])} %, {fmt(ph['mean_residual_T'])} %")
            lines.append(f"| {model} | {r['case']} | {r['floor']:.1f} % | {r['max_depth_over_L']:.2f} | "
                         f"{r['share_F_T']:.0f} % | " + " | ".join(cells) + f" | {fmt(r['after_exit'])} % | "
                         f"{r['params']['phi_deg']:.0f} deg, {r['params']['n']:.2f} |")
    return "\n".join(lines) + "\n"


def forms_table(result: dict) -> str:
    fmt = lambda v: "-" if v is None else f"{v:.1f}"  # noqa: E731
    lines = ["| row | form | one cycle | two cycles | floor |", "|---|---|---|---|---|"]
    for row in ("all unseen", *ROWS.values()):
        for form, res in result["forms"].items():
            s = res["summary"][row]
            lines.append(f"| {row} | {form} | {fmt(s['one cycle'])} % | {fmt(s['two cycles'])} % | "
                         f"{fmt(s['floor'])} % |")
    return "\n".join(lines) + "\n"


def plot(result: dict, cases: dict[str, list[Case]], best: str, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 11))
    ax = fig.add_subplot(3, 1, 1)
    rows = result["phases"]["fee-payload"]
    names = [r["case"].replace("_path", " p").replace("modified_sand", "mod. sand") for r in rows]
    bottom = np.zeros(len(rows))
    for p, colour in zip(PHASES, ("tab:orange", "tab:blue", "tab:green"), strict=True):
        vals = np.array([r["floor"] * r["phases"][p]["share"] / 100.0 for r in rows])
        ax.bar(names, vals, bottom=bottom, color=colour, label=p)
        bottom += vals
    ax.set_ylabel("fee-payload floor [%],\nsplit by share of squared error")
    ax.axhline(8.0, color="k", ls="--", lw=1)
    ax.legend(fontsize=8)
    ax.tick_params(axis="x", labelrotation=30, labelsize=8)
    for k, name in enumerate(("gravel_path1", "gravel_path4", "dirt_path4", "gravel_slope25_path1")):
        case = next(c for cs in cases.values() for c in cs if c.name == name)
        ax = fig.add_subplot(3, 2, 3 + k)
        t = case.filt.path.t[case.idx]
        ax.plot(t, case.y_t, "b-", lw=1.5, label="MPM F_T")
        ax.plot(t, case.y_n, "r-", lw=1.5, label="MPM F_N")
        for form, ls in (("fee-payload", "--"), (best, ":")):
            terms = FORMS[form]
            fit = result["forms"][form]["floor_fits"][name]
            _, f_t, f_n = form_error(case, fit, terms)
            ax.plot(t, f_t, "b" + ls, lw=1.2, label=f"{form} F_T (own fit)")
            ax.plot(t, f_n, "r" + ls, lw=1.2, label=f"{form} F_N")
        a2 = ax.twinx()
        a2.plot(t, case.d, "k-", lw=0.7, alpha=0.5)
        a2.set_ylabel("depth [m]", fontsize=8)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("t [s] (in soil)")
        ax.set_ylabel("force [N]")
        if k == 0:
            ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


#: Candidate offsets of N_gamma for ``--fit-offset``.
OFFSET_GRID = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)


def fit_offset(results: Path, data: Path, payload: PayloadOptions) -> dict:
    """``"fee-payload-depth"``'s offset k (:data:`~wheelloader.estimator.DEFAULT_WEDGE_OFFSET`) from the training
    loops of ``transfer.py``'s split only: the k of :data:`OFFSET_GRID` whose calibration on cycle j of a training
    loop (j = 1, 3) predicts its cycle j + 1 best (median filtered F_R RMSE in soil), as ``transfer.py`` picks its
    held prior."""
    spec = importlib.util.spec_from_file_location("wheelloader_benchmark_transfer",
                                                  Path(__file__).with_name("transfer.py"))
    transfer = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(transfer)
    train = [transfer.Pair(p) for p in transfer.split(data, results)["train"]]
    pairs = [(loop[k], loop[k + 1]) for loop in transfer.loops(train) for k in (0, 2) if len(loop) > k + 1]
    rows = []
    for k in OFFSET_GRID:
        options = CalibrationOptions(force_model="fee-payload", payload=payload,
                                     model_options=ModelOptions(wedge_offset=k))
        nxt, floor = [], []
        for a, b in pairs:
            try:
                cal = calibrate(a.filt, options=options)
            except Exception:  # a loop cycle the calibration refuses (too few in-soil samples)
                continue
            nxt.append(transfer.errors(predict(cal, b.filt), b)["filtered"])
            floor.append(transfer.errors(predict(cal, a.filt), a)["filtered"])
        rows.append({"offset": k, "next_cycle": float(np.median(nxt)), "floor": float(np.median(floor)),
                     "pairs": len(nxt)})
        print(f"offset {k}: training next-cycle {rows[-1]['next_cycle']:.1f} %, floor {rows[-1]['floor']:.1f} % "
              f"({len(nxt)} pairs)", flush=True)
    best = min(rows, key=lambda r: r["next_cycle"])
    return {"rule": "training loops of transfer.py's split, cycle j (1, 3) predicts j + 1; median filtered F_R RMSE",
            "grid": rows, "best": best["offset"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=Path("data/mpm"), help="folder of data/mpm's cycles")
    parser.add_argument("--payload", type=Path, default=Path("docs/results/transfer/transfer.json"),
                        help="transfer.json whose training payload is used (default DEFAULT_PAYLOAD if absent)")
    parser.add_argument("--forms", nargs="+", choices=list(FORMS), default=list(FORMS), help="forms of part 2")
    parser.add_argument("--results", type=Path, default=Path("data/results"),
                        help="folder of the saved loops (transfer.py's training split, for --fit-offset)")
    parser.add_argument("--fit-offset", action="store_true",
                        help="only fit fee-payload-depth's N_gamma offset to the training loops (writes offset.json)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    args = parser.parse_args(argv)
    payload = (PayloadOptions(**json.loads(args.payload.read_text())["payload"]) if args.payload.is_file()
               else DEFAULT_PAYLOAD)
    if args.fit_offset:
        res = fit_offset(args.results, args.data, payload) | {"payload": payload.to_dict(), "machine": machine_info()}
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "offset.json").write_text(json.dumps(res, indent=1) + "\n")
        print(f"best offset {res['best']}")
        return 0
    files = {soil: [args.data / f"{soil}_path{i}.csv" for i in range(1, 5)] for soil in SOILS}
    files["gravel_slope25"] = [args.data / "gravel_slope25_path1.csv"]
    missing = [str(f) for fs in files.values() for f in fs if not f.is_file()]
    if missing:
        print(f"wheelloader: error: missing test cycles {missing}", file=sys.stderr)
        return 2
    cases = {k: [Case(f, payload) for f in fs] for k, fs in files.items()}
    result = {"benchmark": "model_form", "sigma_s": SIGMA, "payload": payload.to_dict(),
              "grid": {"phi_deg": np.degrees(PHI_GRID).tolist(), "delta_deg": np.degrees(DELTA_GRID).tolist(),
                       "n": list(N_GRID)}, "machine": machine_info()}
    result["revision"] = commit_label(result["machine"])
    result["phases"] = phase_study(cases, payload, _error_analysis().phases_of)
    result["forms"] = {}
    for form in args.forms:
        terms = FORMS[form]
        fits: dict[str, dict] = {}

        def fit(group: list[Case], terms=terms, fits=fits) -> dict:
            res = fit_form(group, terms)
            if len(group) == 1:
                fits[group[0].name] = res
            return res

        records = protocol(cases, fit, lambda case, f, terms=terms: form_error(case, f, terms)[0])
        result["forms"][form] = {"terms": list(terms), "records": records, "summary": summary(records),
                                 "floor_fits": fits}
        s = result["forms"][form]["summary"]["all unseen"]
        print(f"form {form}: one {s['one cycle']:.1f}, two {s['two cycles']:.1f}, floor {s['floor']:.1f}", flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "model_form.json").write_text(json.dumps(result, indent=1) + "\n")
    (args.out / "phases.md").write_text(phases_table(result))
    (args.out / "forms.md").write_text(forms_table(result))
    if "fee-payload" in result["forms"]:
        best = min(result["forms"], key=lambda f: result["forms"][f]["summary"]["all unseen"]["floor"])
        plot(result, cases, best, args.out / "model_form.png")
    print(forms_table(result), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
