"""Build the learned correction of ``force_model="fee-learned"`` (the shipped artifact) and compare its forms.

::

    python benchmarks/fee_learned.py --out estimator/learned_weights

One command: it reads the continuum (MPM) cycles, splits them by case family, fits the payload and the
correction on the training families only, and writes ``fee-learned.json`` (the weights, the payload, the
manifest with the split) and ``manifest.json`` (the same manifest, readable alone) and ``report.json`` (the
forms compared side by side). NumPy + SciPy only.

Split by case family (soil x pile x path family), never by sample:

* **train**: the saved MPM loops (``data/results/adaptation_mpm*/cycles``, ``paired_mpm_end55``: gravel and sand
  on the loops' carved piles, the loops' strategies' paths), less any cycle equal to a test cycle (a loop's
  first fixed-path cycle is ``data/mpm``'s path 1), and the new cycles (``data/learn``,
  :mod:`wheelloader.references.mpm.learning_set`) except the validation groups;
* **validation**: every fourth group of ``data/learn`` from the second on (a soil, pile and edge with its three
  paths; whole);
* **test**: ``data/mpm``'s smooth paths (gravel, sand: soils seen, paths not; modified sand and dirt: soils never
  seen; gravel path 1 on the 25 deg pile: a pile angle never seen). Nothing here is fitted to a test cycle.

Training target (module docstring of :mod:`wheelloader.estimator.learned`): for each training group (the cycles
of one soil in one loop folder, or one ``data/learn`` group), ONE ``fee-payload`` soil fitted to all its cycles
at once (``calibrate(list)``; the depth dependence the FEE cannot carry across paths then stays in the
residual), and the residual ``(F_obs - F_FEE) / s`` of every sample from the first contact on (filtered,
sigma 0.1 s; every third sample) against the inputs at that soil. Each cycle weighs alike within its group,
groups by the square root of their size.

Forms compared (``report.json``): the network (tanh, :data:`HIDDEN` units, L2 :data:`L2`, L-BFGS), the same
without the soil inputs, and the ridge quadratic of :mod:`wheelloader.estimator.residual` on the same inputs;
figure: the residual's R2 (variance of the residual explained) on the validation and test families, each
family's residual taken at its own joint soil.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from wheelloader.estimator import CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.learned import INPUT_NAMES, LearnedModel, force_scale, learned_inputs
from wheelloader.estimator.payload import PayloadOptions, fit_payload, payload_contact_state
from wheelloader.provenance import machine_info
from wheelloader.references.filtering import filtered

SIGMA = 0.1
STRIDE = 3
HIDDEN = 16
L2 = 1e-3
MAX_ITER = 1000
SEED = 0
VERSION = "1"
COMMAND = "python benchmarks/fee_learned.py --out estimator/learned_weights"
TEST_ROWS = {"gravel": "gravel", "sand": "sand", "modified_sand": "modified_sand (unseen soil)",
             "dirt": "dirt (held-out soil)", "gravel_slope25": "25 deg pile (held-out pile)"}


def split(data: Path, results: Path, learn: Path) -> dict:
    """The split by case family (module docstring): group name -> list of files, per part."""
    test = {soil: [str(data / f"{soil}_path{i}.csv") for i in range(1, 5)]
            for soil in ("gravel", "sand", "modified_sand", "dirt")}
    test["gravel_slope25"] = [str(data / "gravel_slope25_path1.csv")]
    test_digests = {CycleLog.load(f).content_digest() for files in test.values() for f in files}
    train: dict[str, list[str]] = {}
    dropped = []
    for f in sorted(results.glob("adaptation_mpm*/cycles/**/*.csv.xz")) + sorted(
            results.glob("paired_mpm_end55/cycles/**/*.csv.xz")):
        rel = f.relative_to(results)
        # group: one soil in one experiment folder and seed (its strategies' cycles on their carved piles)
        key = "/".join(rel.parts[:4]) if rel.parts[0].startswith("adaptation") else "/".join(rel.parts[:3])
        if CycleLog.load(f).content_digest() in test_digests:
            dropped.append(str(f))
            continue
        train.setdefault(key, []).append(str(f))
    val: dict[str, list[str]] = {}
    groups = sorted({p.name[:7] for p in learn.glob("learn*.csv.xz")})
    for k, g in enumerate(groups):
        files = sorted(str(p) for p in learn.glob(f"{g}?.csv.xz"))
        (val if k % 4 == 1 else train)[f"learn/{g}"] = files
    return {"rule": "split by case family (soil x pile x path family), never by sample; train: the saved MPM loops "
                    "(gravel, sand; carved piles) less cycles equal to a test cycle, and the data/learn groups but "
                    "every fourth from the second; validation: those data/learn groups (soil, pile, edge, three "
                    "paths); "
                    "test: data/mpm's smooth paths; never trained on: the soils modified_sand and dirt, the 25 deg "
                    "pile", "train": train, "validation": val, "test": test, "dropped_as_test_copies": dropped}


def load(files: list[str]) -> list[CycleLog]:
    return [filtered(CycleLog.load(f), SIGMA) for f in files]


def group_soil(logs: list[CycleLog], payload: PayloadOptions):
    """One fee-payload soil fitted to all ``logs`` at once."""
    opts = CalibrationOptions(force_model="fee-payload", payload=payload)
    return calibrate(logs if len(logs) > 1 else logs[0], options=opts).params


def samples(log: CycleLog, soil, payload: PayloadOptions, stride: int = STRIDE) -> tuple[np.ndarray, np.ndarray]:
    """Inputs and residual over ``s`` of one cycle at ``soil``, from its first contact on, every ``stride``-th."""
    pred = predict(soil, log, force_model="fee-payload", payload=payload)
    state = payload_contact_state(log, payload)
    inside = np.flatnonzero(pred.state.depth > 0.0)
    keep = np.arange(len(log)) >= (inside[0] if inside.size else len(log))
    keep &= (np.arange(len(log)) % stride) == 0
    scale = force_scale(soil.gamma, log.bucket)
    r = np.column_stack([log.tangential - pred.tangential, log.normal - pred.normal]) / scale
    return learned_inputs(state, log.path, log.bucket, soil)[keep], r[keep]


def collect(groups: dict[str, list[str]], payload: PayloadOptions, label: str) -> list[dict]:
    out = []
    for name, files in groups.items():
        logs = load(files)
        t0 = time.process_time()
        soil = group_soil(logs, payload)
        parts = [samples(log, soil, payload) for log in logs]
        out.append({"group": name, "files": files, "soil": soil.to_dict(), "parts": parts})
        print(f"  {label} {name}: {len(logs)} cycles, {sum(len(p[0]) for p in parts)} samples, "
              f"joint fit {time.process_time() - t0:.1f} s CPU", flush=True)
    return out


def stack(groups: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, rs, ws = [], [], []
    for g in groups:
        size = len(g["parts"])
        for x, r in g["parts"]:
            if len(x):
                xs.append(x)
                rs.append(r)
                ws.append(np.full(len(x), 1.0 / (len(x) * math.sqrt(size))))
    w = np.concatenate(ws)
    return np.concatenate(xs), np.concatenate(rs), w / w.sum()


def _unpack(theta: np.ndarray, m: int, h: int):
    k = 0
    w1 = theta[k:k + m * h].reshape(m, h)
    k += m * h
    b1 = theta[k:k + h]
    k += h
    w2 = theta[k:k + 2 * h].reshape(h, 2)
    k += 2 * h
    return w1, b1, w2, theta[k:k + 2]


def train_mlp(x: np.ndarray, r: np.ndarray, w: np.ndarray, hidden: int = HIDDEN, l2: float = L2,
              seed: int = SEED, max_iter: int = MAX_ITER, mask: np.ndarray | None = None) -> LearnedModel:
    """Weighted least squares + L2 on the weights, L-BFGS with the exact gradient; ``mask`` zeroes inputs
    (columns) the form leaves out."""
    from scipy.optimize import minimize

    low, high = np.percentile(x, 0.5, axis=0), np.percentile(x, 99.5, axis=0)
    mean = np.average(x, axis=0, weights=w)
    std = np.sqrt(np.average((x - mean) ** 2, axis=0, weights=w))
    std = np.where(std > 1e-9, std, 1.0)
    z = (np.clip(x, low, high) - mean) / std
    if mask is not None:
        z = z * mask
    m, h = z.shape[1], hidden
    rng = np.random.default_rng(seed)
    theta0 = np.concatenate([rng.normal(0, 1 / math.sqrt(m), m * h), np.zeros(h),
                             rng.normal(0, 1 / math.sqrt(h), 2 * h), np.average(r, axis=0, weights=w)])

    def loss(theta):
        w1, b1, w2, b2 = _unpack(theta, m, h)
        a = np.tanh(z @ w1 + b1)
        e = a @ w2 + b2 - r
        we = e * w[:, None]
        f = float(np.sum(we * e)) + l2 * (float(np.sum(w1 ** 2)) + float(np.sum(w2 ** 2)))
        g_out = 2.0 * we
        g_w2 = a.T @ g_out + 2 * l2 * w2
        g_b2 = g_out.sum(axis=0)
        g_a = (g_out @ w2.T) * (1 - a ** 2)
        g_w1 = z.T @ g_a + 2 * l2 * w1
        g_b1 = g_a.sum(axis=0)
        return f, np.concatenate([g_w1.ravel(), g_b1, g_w2.ravel(), g_b2])

    res = minimize(loss, theta0, jac=True, method="L-BFGS-B", options={"maxiter": max_iter, "maxfun": 2 * max_iter})
    w1, b1, w2, b2 = _unpack(res.x, m, h)
    if mask is not None:
        w1 = w1 * mask[:, None]
    return LearnedModel(w1, b1, w2, b2, mean, std, low, high)


def r2(pred: np.ndarray, r: np.ndarray) -> list[float]:
    return [float(1.0 - np.sum((pred[:, k] - r[:, k]) ** 2) / np.sum((r[:, k] - r[:, k].mean()) ** 2))
            for k in range(2)]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder (estimator/learned_weights ships)")
    parser.add_argument("--data", type=Path, default=Path("data/mpm"))
    parser.add_argument("--results", type=Path, default=Path("data/results"))
    parser.add_argument("--learn", type=Path, default=Path("data/learn"))
    args = parser.parse_args(argv)
    for folder in (args.data, args.results):
        if not folder.is_dir():
            print(f"wheelloader: error: {folder} is not a folder", file=sys.stderr)
            return 2
    t0 = time.process_time()
    parts = split(args.data, args.results, args.learn)
    train_files = [f for files in parts["train"].values() for f in files]
    print(f"train {len(train_files)} cycles in {len(parts['train'])} groups; validation "
          f"{sum(map(len, parts['validation'].values()))}; test {sum(map(len, parts['test'].values()))}", flush=True)
    payload = fit_payload([CycleLog.load(f) for f in train_files])
    print(f"payload {payload}", flush=True)
    train = collect(parts["train"], payload, "train")
    val = collect(parts["validation"], payload, "validation")
    test = collect(parts["test"], payload, "test")
    x, r, w = stack(train)
    forms = {}
    no_soil = np.array([0.0 if n in ("tan_phi", "tan_delta", "cohesion_number", "adhesion_number") else 1.0
                        for n in INPUT_NAMES])
    models = {"mlp": train_mlp(x, r, w), "mlp without soil inputs": train_mlp(x, r, w, mask=no_soil)}
    from wheelloader.estimator.residual import _design

    zmean, zstd = x.mean(axis=0), np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    design = _design((x - zmean) / zstd)
    gram = design.T @ (design * w[:, None])
    ridge = np.linalg.solve(gram + 1e-3 * np.trace(gram) / len(gram) * np.eye(len(gram)), design.T @ (r * w[:, None]))

    def ridge_predict(xx):
        return _design((np.clip(xx, x.min(axis=0), x.max(axis=0)) - zmean) / zstd) @ ridge

    predictors = {**{k: m.correction for k, m in models.items()}, "ridge quadratic": ridge_predict}
    for name, fn in predictors.items():
        rows = {"train": r2(fn(x), r)}
        for label, groups in (("validation", val), *((TEST_ROWS[g["group"]], [g]) for g in test)):
            gx, gr, _ = stack(groups) if groups else (None, None, None)
            rows[label] = r2(fn(gx), gr) if gx is not None else None
        forms[name] = {"r2_tangential_normal": rows}
        print(f"{name}: {json.dumps(rows)}", flush=True)
    model = models["mlp"]
    manifest = {"version": VERSION, "command": COMMAND, "form": f"tanh MLP, {HIDDEN} hidden units, L2 {L2}",
                "inputs": list(INPUT_NAMES), "trusted_range": {"low": model.low.tolist(), "high": model.high.tolist()},
                "payload": payload.to_dict(), "split": parts,
                "group_soils": {g["group"]: g["soil"] for g in train + val + test},
                "training_samples": int(len(x)), "forms": forms, "sigma_s": SIGMA, "stride": STRIDE}
    model = LearnedModel(model.w1, model.b1, model.w2, model.b2, model.mean, model.std, model.low, model.high,
                         version=VERSION, manifest=manifest)
    args.out.mkdir(parents=True, exist_ok=True)
    model.save(args.out / "fee-learned.json")
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    report = {"benchmark": "fee_learned", "forms": forms, "cpu_s": time.process_time() - t0, "machine": machine_info()}
    (args.out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    print(f"wrote {args.out} in {report['cpu_s']:.0f} s CPU", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
