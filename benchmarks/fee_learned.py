"""Build the learned correction of ``force_model="fee-learned"`` (the shipped artifact) and compare its forms.

::

    python benchmarks/fee_learned.py --out estimator/learned_weights

One command: it reads the continuum (MPM) cycles, splits them by case family, takes the payload
``benchmarks/transfer.py`` chooses (:func:`transfer_payload`: its recipe, fitted to its training and extra cycles,
chosen on its validation loops; so the kept fill ``fee-learned`` predicts is the validated one; its extra cycles
hold the ``data/learn`` cycles its ``manifest.json`` lists, validation groups included: their kept fill, never
their forces), fits the correction on the training families only, and writes ``fee-learned.json`` (the
weights, the payload, the manifest with the split) and ``manifest.json`` (the same manifest, readable alone) and
``report.json`` (the forms compared side by side). NumPy + SciPy only.

Split by case family (soil x pile x path family), never by sample:

* **train**: the saved MPM loops of the base and curl-out runs (``data/results/adaptation_mpm``,
  ``adaptation_mpm_curlout``: gravel and sand on the loops' carved piles, the loops' strategies' paths), less any
  cycle equal to a test cycle (a loop's first fixed-path cycle is ``data/mpm``'s path 1), and the new cycles
  (``data/learn``, :mod:`wheelloader.references.mpm.learning_set`) except the validation groups;
* **validation**: the end55 path family (``adaptation_mpm_end55``, ``paired_mpm_end55``: the loops
  ``benchmarks/transfer.py`` scales its bands on, so that scale is not taken on training cycles) and every fourth
  group of ``data/learn`` by its number, 01, 05, 09, ... (a soil, pile and edge with its three paths; whole; the
  rule of :func:`wheelloader.references.mpm.learning_set.group_part`, stated in ``data/learn/manifest.json``);
* **test**: ``data/mpm``'s smooth paths (gravel, sand: soils seen, paths not; modified sand and dirt: soils never
  seen; gravel path 1 on the 25 deg pile: a pile angle never seen). Nothing here is fitted to a test cycle.

Training target: what calibrate-then-predict meets. For each training cycle, the soil a one-cycle
``fee-payload`` calibration finds (the soil ``calibrate(log, force_model="fee-learned")`` fits and the correction
is evaluated at); at that soil, the residual ``(F_obs - F_FEE) / s`` of the cycle itself (the floor) and of
:data:`CROSS` other cycles of its group (the same soil, other paths: the transfer), in soil (the correction is
gated to 0 out of it), filtered (sigma 0.1 s), every :data:`STRIDE`-th sample, against the inputs at that soil.
The own path and the other paths weigh half each per calibration cycle; groups (one soil in one loop folder, or
one ``data/learn`` group) by the square root of their size. So the soil inputs span the soils one-cycle fits
find (one per training cycle, not one per group), and the network is used at prediction where it was trained.

Forms compared (``report.json``, :data:`FORMS`): the network (tanh, L-BFGS, :data:`MAX_ITER` iterations) as the
mean of :data:`ENSEMBLE` seeds (packed into one network), by hidden units, L2, the loops' share, the inputs left
out and the smoothness penalty (:func:`smoothness_penalty`: the input gradient and curvature along the path inputs
at the training samples, jittered copies and points over the trusted box, and the network's size over that box);
figures: calibrate-then-predict on the validation families (each cycle from each other one, the F_R RMSE in
soil, median, % of the mean observed |F_R|; ``fee-payload-depth`` beside), the R2 of the transfer residual on
the validation and test families, and the planner's cold plans with the form's network (:func:`cold_plans`:
IPOPT iterations, CPU, the check). Among the forms the planner can carry (:func:`plannable`: no kept-fill input,
every cold plan solved and checked, median iterations at most the FEE's), the one with the lower validation
median is written. ``--learning-curve N ...``
retrains it on :data:`CURVE_DRAWS` seeded random subsets of N training groups each (``report.json``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

from wheelloader.estimator import CycleLog
from wheelloader.estimator.calibration import CalibrationOptions, calibrate, predict
from wheelloader.estimator.force_models import LEARNED_BASE
from wheelloader.estimator.learned import (
    CALIBRATION_PASSES,
    INPUT_NAMES,
    LearnedModel,
    contact_gate,
    corrected_log,
    force_scale,
    learned_inputs,
)
from wheelloader.estimator.payload import PayloadOptions, payload_contact_state
from wheelloader.provenance import machine_info
from wheelloader.references.filtering import filtered
from wheelloader.references.mpm.learning_set import group_part

SIGMA = 0.1
STRIDE = 3
CROSS = 3
HIDDEN = 4
L2 = 1e-1
MAX_ITER = 300
SEED = 0
ENSEMBLE = 3
#: Random subsets of the training groups per size of the learning curve (``--learning-curve``).
CURVE_DRAWS = 3
#: The loop cycles' share of the training weight (carved piles in two soils: not the test's path family).
LOOP_SHARE = 0.2
#: Standard deviations (of the standardised inputs) by which the smoothness penalty's extra points are jittered.
JITTER = 0.5
#: Every this many-th training sample carries the smoothness penalty (and as many jittered and box points).
PENALTY_STRIDE = 4
VERSION = "6"
COMMAND = "python benchmarks/fee_learned.py --out estimator/learned_weights"
TEST_ROWS = {"gravel": "gravel", "sand": "sand", "modified_sand": "modified_sand (unseen soil)",
             "dirt": "dirt (held-out soil)", "gravel_slope25": "25 deg pile (held-out pile)"}
SOIL_INPUTS = ("tan_phi", "tan_delta", "cohesion_number", "adhesion_number")


class Form(NamedTuple):
    """One form of the correction the build compares: hidden units a seed, L2, the loop cycles' share of the
    training weight, the inputs it leaves out (their columns zeroed), the smoothness penalty's weights
    (:func:`smoothness_penalty`, :func:`train_mlp`'s ``box``) and the first of its :data:`ENSEMBLE` seeds."""

    hidden: int
    l2: float
    share: float
    drop: tuple[str, ...] = ("kept_fill_fraction",)
    slope: float = 0.0
    curvature: float = 0.0
    box: float = 0.0
    seed: int = SEED

    @property
    def mask(self) -> np.ndarray | None:
        return np.array([0.0 if n in self.drop else 1.0 for n in INPUT_NAMES]) if self.drop else None

    def train(self, x: np.ndarray, r: np.ndarray, w: np.ndarray) -> LearnedModel:
        """The mean of :data:`ENSEMBLE` seeds of this form trained on ``x, r, w`` (:func:`train_mlp`)."""
        return mean_network([train_mlp(x, r, w, hidden=self.hidden, l2=self.l2, seed=self.seed + k, mask=self.mask,
                                       slope=self.slope, curvature=self.curvature, box=self.box)
                             for k in range(ENSEMBLE)])


#: The forms compared (weights v7): v6's shipped form; v6's freer form (it beat the base on validation, not the
#: planner), also from other seeds (how far the figures move by the seeds alone); and that freer form with the
#: penalties that brought its cold plans near the FEE's (the box; docs/results/learned.md, "v7", for the others
#: tried: the slope and curvature at the samples alone did not).
_FREE = f"mlp 8 units, L2 0.001, loops {LOOP_SHARE}, no kept-fill input"
FORMS = {
    "mlp 8 units, L2 0.1, no loops, no kept-fill input (v6)": Form(8, 1e-1, 0.0),
    _FREE: Form(8, 1e-3, LOOP_SHARE),
    f"{_FREE}, seeds 3-5": Form(8, 1e-3, LOOP_SHARE, seed=3),
    f"{_FREE}, box 1": Form(8, 1e-3, LOOP_SHARE, box=1.0),
    f"{_FREE}, slope 0.01, box 1": Form(8, 1e-3, LOOP_SHARE, slope=1e-2, box=1.0),
}


def split(data: Path, results: Path, learn: Path) -> dict:
    """The split by case family (module docstring): group name -> list of files, per part (``train_loops``: the
    down-weighted loop cycles, :data:`LOOP_SHARE`)."""
    test = {soil: [str(data / f"{soil}_path{i}.csv") for i in range(1, 5)]
            for soil in ("gravel", "sand", "modified_sand", "dirt")}
    test["gravel_slope25"] = [str(data / "gravel_slope25_path1.csv")]
    test_digests = {CycleLog.load(f).content_digest() for files in test.values() for f in files}
    train: dict[str, list[str]] = {}
    loops: dict[str, list[str]] = {}
    val: dict[str, list[str]] = {}
    val_loops: dict[str, list[str]] = {}
    dropped = []
    for run in ("adaptation_mpm", "adaptation_mpm_curlout", "adaptation_mpm_end55", "paired_mpm_end55"):
        for f in sorted((results / run).glob("cycles/**/*.csv.xz")):
            rel = f.relative_to(results)
            # group: one soil in one experiment folder and seed (its strategies' cycles on their carved piles)
            key = "/".join(rel.parts[:4]) if rel.parts[0].startswith("adaptation") else "/".join(rel.parts[:3])
            if CycleLog.load(f).content_digest() in test_digests:
                dropped.append(str(f))
                continue
            (val_loops if run.endswith("end55") else loops).setdefault(key, []).append(str(f))
    for g in sorted({p.name[:7] for p in learn.glob("learn*.csv.xz")}):
        files = sorted(str(p) for p in learn.glob(f"{g}?.csv.xz"))
        (val if group_part(g) == "validation" else train)[f"learn/{g}"] = files
    return {"rule": "split by case family (soil x pile x path family), never by sample; train: the data/learn "
                    "groups (smooth, varied paths, soils, piles, edges) but every fourth by number from 01 on "
                    "(learning_set.group_part: 01, 05, 09, ...), and, "
                    f"down-weighted to {LOOP_SHARE} of the training weight, the saved MPM loops of the base and "
                    "curl-out runs (gravel, sand; carved piles) less cycles equal to a test cycle; validation: "
                    "those data/learn groups (soil, pile, edge, three paths; the form is chosen on them) and the "
                    "end55 loop family (adaptation_mpm_end55, paired_mpm_end55; reported, transfer.py scales its "
                    "bands on them); test: data/mpm's smooth paths (transfer.py's test split; data/mpm has no "
                    "training part there); never trained on: the soils modified_sand and dirt, the 25 deg pile",
            "train": {**train, **loops}, "train_learn": train, "train_loops": loops,
            "validation": {**val, **val_loops}, "validation_learn": val, "validation_loops": val_loops,
            "test": test, "dropped_as_test_copies": dropped}


def _benchmark(name: str):
    """Another benchmark script of this folder, imported as a module (the benchmarks are not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"wheelloader_benchmark_{name}",
                                                  Path(__file__).with_name(f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def transfer_payload(data: Path, results: Path) -> tuple[PayloadOptions, dict]:
    """The payload ``benchmarks/transfer.py`` chooses (its :func:`split` and :func:`select_payload`: the candidate
    recipe whose kept fill predicts its validation loops best, fitted to its training loops and, where the recipe
    says so, its ``payload_extra`` cycles; test copies dropped), and the chosen recipe."""
    tr = _benchmark("transfer")
    parts = tr.split(data, results)
    train = [tr.Pair(p) for p in parts["train"]]
    validation = [tr.Pair(p) for p in parts["validation"]]
    test = {k: [tr.Pair(p) for p in v] for k, v in parts["test"].items()}
    extra = [CycleLog.load(p) for p in parts["payload_extra"]]
    payload, selection = tr.select_payload(train, extra, validation, test)
    chosen = selection["candidates"][selection["chosen"]]
    recipe = {k: chosen[k] for k in ("cycles", "samples", "curl", "max_kept_ratio", "validation_median")}
    return payload, {"recipe": recipe, "by": "benchmarks/transfer.py (select_payload, chosen on its validation loops)",
                     "train_cycles": len(train), "extra_cycles": len(extra)}


def load(files: list[str]) -> list[CycleLog]:
    return [filtered(CycleLog.load(f), SIGMA) for f in files]


def one_cycle_soil(log: CycleLog, payload: PayloadOptions):
    """The soil a one-cycle ``fee-payload`` calibration finds (what ``fee-learned`` fits; None if refused)."""
    try:
        return calibrate(log, options=CalibrationOptions(force_model=LEARNED_BASE, payload=payload)).params
    except Exception:  # too few in-soil samples: the calibration refuses it, so does the build
        return None


class Cycle:
    """One cycle: its filtered log, its payload contact state (soil-free) and its one-cycle soil."""

    def __init__(self, path: str, payload: PayloadOptions) -> None:
        self.path = path
        self.log = filtered(CycleLog.load(path), SIGMA)
        self.state = payload_contact_state(self.log, payload)
        self.soil = one_cycle_soil(self.log, payload)


def samples(cycle: Cycle, soil, payload: PayloadOptions, stride: int = STRIDE
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inputs, residual over ``s`` and F_R-error parts of ``cycle`` at ``soil``: in-soil samples, every
    ``stride``-th (``stride`` 1: all, for the F_R figures)."""
    log = cycle.log
    pred = predict(soil, log, force_model=LEARNED_BASE, payload=payload)
    keep = np.flatnonzero(pred.state.depth > 0.0)
    keep = keep[keep % stride == 0] if stride > 1 else keep
    scale = force_scale(soil.gamma, log.bucket)
    r = np.column_stack([log.tangential - pred.tangential, log.normal - pred.normal]) / scale
    fee = np.column_stack([pred.tangential, pred.normal]) / scale
    return learned_inputs(cycle.state, log.path, log.bucket, soil)[keep], r[keep], fee[keep]


def collect(groups: dict[str, list[str]], payload: PayloadOptions, label: str, seed: int = SEED) -> list[dict]:
    """Per group: its cycles, and per calibration cycle the blocks (own path, :data:`CROSS` others) at its
    one-cycle soil (module docstring)."""
    rng = np.random.default_rng(seed)
    out = []
    for name, files in groups.items():
        t0 = time.process_time()
        cycles = [Cycle(f, payload) for f in files]
        fitted = [c for c in cycles if c.soil is not None]
        blocks = []
        for c in fitted:
            others = [o for o in cycles if o is not c]
            picks = rng.choice(len(others), size=min(CROSS, len(others)), replace=False) if others else []
            blocks.append({"calibrated": c.path, "own": samples(c, c.soil, payload),
                           "cross": [samples(others[k], c.soil, payload) for k in sorted(picks)]})
        out.append({"group": name, "files": files, "cycles": cycles, "blocks": blocks,
                    "soils": {c.path: c.soil.to_dict() for c in fitted}})
        print(f"  {label} {name}: {len(cycles)} cycles ({len(fitted)} calibrated), "
              f"{sum(len(b['own'][0]) + sum(len(x[0]) for x in b['cross']) for b in blocks)} samples, "
              f"{time.process_time() - t0:.1f} s CPU", flush=True)
    return out


def stack(groups: list[dict], parts: tuple[str, ...] = ("own", "cross"), loops: list[dict] | None = None,
          loop_share: float = 0.0) -> tuple[np.ndarray, ...]:
    """Inputs, targets and weights (summing to 1) of the groups' blocks (module docstring); ``loops``' blocks
    beside them weigh ``loop_share`` of the whole (0: left out)."""
    if loops and loop_share > 0.0:
        x1, r1, w1 = stack(groups, parts)
        x2, r2_, w2 = stack(loops, parts)
        return (np.concatenate([x1, x2]), np.concatenate([r1, r2_]),
                np.concatenate([(1.0 - loop_share) * w1, loop_share * w2]))
    xs, rs, ws = [], [], []
    for g in groups:
        size = math.sqrt(max(len(g["blocks"]), 1))
        for b in g["blocks"]:
            chunks = ([(b["own"], 0.5)] if "own" in parts else []) + (
                [(x, 0.5 / len(b["cross"])) for x in b["cross"]] if "cross" in parts else [])
            for (x, r, _), share in chunks:
                if len(x):
                    xs.append(x)
                    rs.append(r)
                    ws.append(np.full(len(x), share / (len(x) * size)))
    if not xs:
        return None, None, None
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


def smoothness_penalty(z: np.ndarray, pw: np.ndarray, w1: np.ndarray, b1: np.ndarray, w2: np.ndarray,
                       rows: np.ndarray, slope: float, curvature: float) -> tuple[float, tuple[np.ndarray, ...]]:
    """How steeply and how sharply the network bends where the planner moves: ``slope`` times the weighted mean of
    ``|d MLP / d z_P|_F^2`` plus ``curvature`` times that of ``|d^2 MLP / d z_P^2|_F^2`` at the points ``z``
    (weights ``pw``, summing to 1), ``P`` the standardised inputs ``rows`` (a 0/1 vector: the path's, which the
    planner's decision variables move; not the soil's, fixed within a plan), and its exact gradient
    (``w1, b1, w2``).

    With ``a = tanh(z W1 + b1)``, ``s = 1 - a^2`` and ``t = -2 a s`` (its derivative), the Jacobian of sample
    ``n`` is ``W1_P diag(s_n) W2``, so ``|J_n|_F^2 = s_n^T (G1 o G2) s_n`` with ``G1 = W1_P^T W1_P`` and
    ``G2 = W2 W2^T`` (``o`` the elementwise product); the Hessian's is ``t_n^T (G1 o G1 o G2) t_n``. Cost:
    samples x hidden^2, not samples x inputs^2.
    """
    w1p = w1 * rows[:, None]
    g1, g2 = w1p.T @ w1p, w2 @ w2.T
    a = np.tanh(z @ w1 + b1)
    s = 1.0 - a * a
    value = 0.0
    d_u = np.zeros_like(a)
    d_g1 = np.zeros_like(g1)
    d_g2 = np.zeros_like(g2)
    for weight, q, dq_du, power in ((slope, s, -2.0 * a * s, 1), (curvature, -2.0 * a * s, s * (6.0 * a * a - 2.0), 2)):
        if weight <= 0.0:
            continue
        m = g1 ** power * g2
        qm = q @ m
        value += weight * float(np.sum(pw * np.sum(qm * q, axis=1)))
        d_u += weight * 2.0 * pw[:, None] * qm * dq_du
        outer = weight * (q * pw[:, None]).T @ q  # d value / d m
        d_g1 += outer * power * g1 ** (power - 1) * g2
        d_g2 += outer * g1 ** power
    d_w1 = z.T @ d_u + 2.0 * w1p @ d_g1
    return value, (d_w1, d_u.sum(axis=0), 2.0 * d_g2 @ w2)


def train_mlp(x: np.ndarray, r: np.ndarray, w: np.ndarray, hidden: int = HIDDEN, l2: float = L2,
              seed: int = SEED, max_iter: int = MAX_ITER, mask: np.ndarray | None = None, slope: float = 0.0,
              curvature: float = 0.0, jitter: float = JITTER, box: float = 0.0) -> LearnedModel:
    """Weighted least squares of the gated network (:func:`~wheelloader.estimator.learned.contact_gate` of the
    contact ramp, input 1) + L2 on the weights + the smoothness penalty (:func:`smoothness_penalty`, ``slope``
    and ``curvature``, at the training samples and at as many seeded copies jittered by ``jitter`` standard
    deviations and as many points uniform over the trusted box of the path inputs (the range the inputs are clipped
    to, each at the soil of a random training sample), a third of the weight each; every :data:`PENALTY_STRIDE`-th
    training sample), ``box`` times the mean squared network output at the box points (it shrinks where there is
    no data, where the planner's iterates go), L-BFGS with the exact gradient; ``mask`` zeroes inputs (columns)
    the form leaves out."""
    from scipy.optimize import minimize

    low, high = np.percentile(x, 0.5, axis=0), np.percentile(x, 99.5, axis=0)
    mean = np.average(x, axis=0, weights=w)
    std = np.sqrt(np.average((x - mean) ** 2, axis=0, weights=w))
    std = np.where(std > 1e-9, std, 1.0)
    z = (np.clip(x, low, high) - mean) / std
    if mask is not None:
        z = z * mask
    gate = contact_gate(x[:, 1])[:, None]
    m, h = z.shape[1], hidden
    rng = np.random.default_rng(seed)
    theta0 = np.concatenate([rng.normal(0, 1 / math.sqrt(m), m * h), np.zeros(h),
                             rng.normal(0, 1 / math.sqrt(h), 2 * h), np.average(r, axis=0, weights=w)])
    smooth = slope > 0.0 or curvature > 0.0 or box > 0.0
    if smooth:
        keep = 1.0 if mask is None else mask
        path = np.array([0.0 if n in SOIL_INPUTS else 1.0 for n in INPUT_NAMES])
        rows = path * keep
        prng = np.random.default_rng(seed + 1000)
        sub = np.arange(0, len(z), PENALTY_STRIDE)
        jittered = (z[sub] + jitter * prng.standard_normal((len(sub), m))) * keep
        # the planner's whole trusted box: path inputs uniform in their clip range, the soil of a training sample
        boxed = np.where(path > 0.0, prng.uniform(low, high, (len(sub), m)), x[prng.choice(len(x), len(sub))])
        boxed = (np.clip(boxed, low, high) - mean) / std * keep
        zp = np.concatenate([z[sub], jittered, boxed])
        ws = w[sub] / w[sub].sum()
        pw = np.concatenate([ws, ws, np.full(len(sub), 1.0 / len(sub))]) / 3.0

    def loss(theta):
        w1, b1, w2, b2 = _unpack(theta, m, h)
        a = np.tanh(z @ w1 + b1)
        e = gate * (a @ w2 + b2) - r
        we = e * w[:, None]
        f = float(np.sum(we * e)) + l2 * (float(np.sum(w1 ** 2)) + float(np.sum(w2 ** 2)))
        g_out = 2.0 * we * gate
        g_w2 = a.T @ g_out + 2 * l2 * w2
        g_b2 = g_out.sum(axis=0)
        g_a = (g_out @ w2.T) * (1 - a ** 2)
        g_w1 = z.T @ g_a + 2 * l2 * w1
        g_b1 = g_a.sum(axis=0)
        if smooth:
            p, (p_w1, p_b1, p_w2) = smoothness_penalty(zp, pw, w1, b1, w2, rows, slope, curvature)
            f, g_w1, g_b1, g_w2 = f + p, g_w1 + p_w1, g_b1 + p_b1, g_w2 + p_w2
        if box > 0.0:  # the network's size over the trusted box (where data is sparse, the correction shrinks)
            ab = np.tanh(boxed @ w1 + b1)
            ob = 2.0 * box / len(boxed) * (ab @ w2 + b2)
            f += 0.5 * float(np.sum(ob * (ab @ w2 + b2)))
            g_ab = (ob @ w2.T) * (1 - ab ** 2)
            g_w1, g_b1 = g_w1 + boxed.T @ g_ab, g_b1 + g_ab.sum(axis=0)
            g_w2, g_b2 = g_w2 + ab.T @ ob, g_b2 + ob.sum(axis=0)
        return f, np.concatenate([g_w1.ravel(), g_b1, g_w2.ravel(), g_b2])

    res = minimize(loss, theta0, jac=True, method="L-BFGS-B", options={"maxiter": max_iter, "maxfun": 2 * max_iter})
    w1, b1, w2, b2 = _unpack(res.x, m, h)
    if mask is not None:
        w1 = w1 * mask[:, None]
    return LearnedModel(w1, b1, w2, b2, mean, std, low, high)


#: The soils of the build's cold plans (one each; IPOPT's iterations are deterministic, CPU is reported beside).
PLAN_SOILS = ("gravel", "sand", "dirt")
#: IPOPT's statuses of a solved plan.
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def cold_plans(force_model: str, model: LearnedModel | None = None, soils: tuple[str, ...] = PLAN_SOILS) -> dict:
    """What a form costs the planner (#32: the cold plan <= 1.5x the FEE's): ``force_model``'s cold plans
    (``benchmarks/force_model_costs.py``'s: the default pile, the env's nominal start, the default initial guess)
    on ``soils``, with ``model`` as ``"fee-learned"``'s network in place of the shipped weights (the NLP built
    afresh: neither the in-memory nor the disk cache of NLPs is used). IPOPT's iterations (median; they do not
    depend on the machine), the CPU seconds (median), and how many plans pass the NumPy model's check."""
    import os
    import statistics

    import wheelloader.estimator.learned as learned_module
    import wheelloader.planner.verify as verify_module
    from wheelloader.estimator import Pile
    from wheelloader.planner import PlannerOptions, TrajectoryOptimizer, cycle_duration, default_start, nlp, verify_plan

    saved = (learned_module.default_learned_model, verify_module.default_learned_model,
             os.environ.get("WHEELLOADER_NLP_CACHE"))
    if model is not None:
        learned_module.default_learned_model = verify_module.default_learned_model = lambda: model
    os.environ["WHEELLOADER_NLP_CACHE"] = "off"
    nlp.release()
    try:
        pile = Pile.trapezoid()
        start = default_start(pile)
        duration = cycle_duration(pile, start)
        opt = TrajectoryOptimizer(options=PlannerOptions(force_model=force_model))
        rows = []
        for soil in soils:
            opt.reset_warm_start()
            cpu = time.process_time()
            plan = opt.solve(soil, pile, start, duration)
            cpu = time.process_time() - cpu
            check = verify_plan(plan, soil, pile, opt.bucket, opt.loader, opt.options)
            rows.append({"soil": soil, "iterations": int(plan.iterations), "cpu_s": cpu, "status": plan.status,
                         "check_ok": bool(check.ok)})
    finally:
        learned_module.default_learned_model, verify_module.default_learned_model = saved[:2]
        if saved[2] is None:
            os.environ.pop("WHEELLOADER_NLP_CACHE")
        else:
            os.environ["WHEELLOADER_NLP_CACHE"] = saved[2]
        nlp.release()
    return {"iterations_median": float(statistics.median(r["iterations"] for r in rows)),
            "cpu_median_s": float(statistics.median(r["cpu_s"] for r in rows)),
            "passing": sum(r["check_ok"] for r in rows), "plans": rows}


def with_payload(model: LearnedModel, payload: PayloadOptions) -> LearnedModel:
    """``model`` carrying ``payload`` (:attr:`LearnedModel.payload`, what ``"fee-learned"``'s planner and env keep;
    a network without a manifest keeps the default payload)."""
    return LearnedModel(model.w1, model.b1, model.w2, model.b2, model.mean, model.std, model.low, model.high,
                        version=model.version, manifest={**(model.manifest or {}), "payload": payload.to_dict()})


def plannable(form: Form, plans: dict, fee_plans: dict) -> bool:
    """The planner's gate of the build (docs/results/learned.md, "v7"): a form may ship only if it leaves the
    kept-fill input out (with it the cold plan took 2.57x the FEE's, weights v4), all its cold plans
    (:func:`cold_plans`) are solved and pass the NumPy model's check, and their median IPOPT iterations are at
    most the FEE's (iterations, not CPU: the choice does not depend on the machine)."""
    solved = all(p["status"] in SOLVED and p["check_ok"] for p in plans["plans"])
    return "kept_fill_fraction" in form.drop and solved and plans["iterations_median"] <= fee_plans["iterations_median"]


def mean_network(ms: list[LearnedModel]) -> LearnedModel:
    """The mean of networks trained on the same samples (:func:`train_mlp`, other seeds) as one network: their
    hidden units side by side, their output weights over their number (exact: same range and standardisation)."""
    members = len(ms)
    return LearnedModel(np.hstack([m.w1 for m in ms]), np.concatenate([m.b1 for m in ms]),
                        np.vstack([m.w2 for m in ms]) / members, sum(m.b2 for m in ms) / members,
                        ms[0].mean, ms[0].std, ms[0].low, ms[0].high)


def r2(pred: np.ndarray, r: np.ndarray) -> list[float]:
    return [float(1.0 - np.sum((pred[:, k] - r[:, k]) ** 2) / np.sum((r[:, k] - r[:, k].mean()) ** 2))
            for k in range(2)]


def transfer_errors(groups: list[dict], payload: PayloadOptions, model: LearnedModel | None = None,
                    passes: int = 0) -> dict[str, float]:
    """Calibrate-then-predict within each group (each cycle from each other one): the median in-soil F_R RMSE
    [% of the mean observed |F_R|] of the other paths (``one_cycle``) and of the cycle itself (``floor``), with
    ``model``'s correction (None: ``fee-payload`` alone) after ``passes`` fixed-point fits of the calibration
    (:data:`~wheelloader.estimator.learned.CALIBRATION_PASSES`)."""
    out: dict[str, list[float]] = {"one_cycle": [], "floor": []}
    opts = CalibrationOptions(force_model=LEARNED_BASE, payload=payload)
    for g in groups:
        for c in g["cycles"]:
            if c.soil is None:
                continue
            soil = c.soil
            for _ in range(passes if model is not None else 0):
                soil = calibrate(corrected_log(model, c.log, soil, payload)[0], options=opts).params
            for o in g["cycles"]:
                x, r, fee = samples(o, soil, payload, stride=1)
                if not len(x):
                    continue
                pred = fee + (0.0 if model is None else model.correction(x))
                obs = fee + r
                fr_p, fr_o = np.hypot(pred[:, 0], pred[:, 1]), np.hypot(obs[:, 0], obs[:, 1])
                err = 100.0 * math.sqrt(float(np.mean((fr_p - fr_o) ** 2))) / float(np.mean(fr_o))
                out["floor" if o is c else "one_cycle"].append(err)
    return {k: float(np.median(v)) if v else float("nan") for k, v in out.items()}


def learning_curve(train: list[dict], loops: list[dict], form: Form, val: list[dict], payload: PayloadOptions,
                   sizes: list[int], draws: int = CURVE_DRAWS) -> list[dict]:
    """Would more groups help? The form ``form`` (the loop cycles kept whole)
    retrained on ``draws`` seeded random subsets of ``sizes`` of the ``data/learn`` training groups (all of them:
    once), each judged as the shipped form is: calibrate-then-predict within the validation groups."""
    out = []
    for size in sizes:
        if not 1 <= size <= len(train):
            raise ValueError(f"--learning-curve: {size} groups, not between 1 and {len(train)}")
        rows = []
        for draw in range(draws if size < len(train) else 1):
            pick = sorted(np.random.default_rng(draw).choice(len(train), size, replace=False).tolist())
            x, r, w = stack([train[k] for k in pick], loops=loops, loop_share=form.share)
            m = form.train(x, r, w)
            rows.append({"groups": [train[k]["group"] for k in pick],
                         **transfer_errors(val, payload, m, CALIBRATION_PASSES)})
        out.append({"training_groups": size, "draws": rows,
                    "one_cycle_median": float(np.median([d["one_cycle"] for d in rows])),
                    "floor_median": float(np.median([d["floor"] for d in rows]))})
        print(f"learning curve, {size} groups: {json.dumps(out[-1]['draws'][0])} ...", flush=True)
    return out


def forms_table(report: dict) -> str:
    """The side-by-side table of the forms (markdown) from a build's ``report.json``: validation (one cycle /
    floor), the R2 of the transfer residual (training, validation; F_T / F_N), the planner's cold plans (IPOPT
    iterations per soil, median; CPU median against the FEE's in the same build) and the gate. Test rows are not
    in it (they are in the report; the form is chosen without them)."""
    fee = report["fee_cold_plans"]
    lines = ["| form | validation, one cycle / floor | R2 train | R2 validation | cold plan iterations (gravel, sand, "
             "dirt; median) | cold plan CPU vs fee | planner gate | chosen |", "|---|---|---|---|---|---|---|---|"]
    fee_its = ", ".join(str(p["iterations"]) for p in fee["plans"])
    lines.append(f"| fee (the planner gate's reference) | | | | {fee_its}; {fee['iterations_median']:.0f} | 1.00x "
                 "| | |")
    for name, f in report["forms"].items():
        val = f"{f['validation']['one_cycle']:.1f} / {f['validation']['floor']:.1f} %"
        if "planner" not in f:
            lines.append(f"| {name} | {val} | | | | | | |")
            continue
        r2s = f["r2_tangential_normal_transfer"]
        plans = f["planner"]
        its = ", ".join(str(p["iterations"]) + ("" if p["status"] in SOLVED else " (not solved)")
                        for p in plans["plans"])
        lines.append(f"| {name} | {val} | {r2s['train'][0]:.2f} / {r2s['train'][1]:.2f} | "
                     f"{r2s['validation'][0]:.2f} / {r2s['validation'][1]:.2f} | {its}; "
                     f"{plans['iterations_median']:.0f} | {plans['cpu_median_s'] / fee['cpu_median_s']:.2f}x | "
                     f"{'passes' if f['plannable'] else 'fails'} | {'yes' if name == report['chosen'] else ''} |")
    return "\n".join(lines) + "\n"


def write_report(out: Path, fields: dict, argv: list[str] | None, t0: float) -> dict:
    """Write ``report.json`` (``fields``, the command, the CPU seconds since ``t0``, the machine) and ``forms.md``
    (:func:`forms_table`) into ``out``; return the report."""
    report = {"benchmark": "fee_learned", **fields,
              "command": " ".join(["python benchmarks/fee_learned.py", *(argv if argv is not None else sys.argv[1:])]),
              "cpu_s": time.process_time() - t0, "machine": machine_info()}
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    (out / "forms.md").write_text(forms_table(report))
    return report


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder (estimator/learned_weights ships)")
    parser.add_argument("--data", type=Path, default=Path("data/mpm"))
    parser.add_argument("--results", type=Path, default=Path("data/results"))
    parser.add_argument("--learn", type=Path, default=Path("data/learn"))
    parser.add_argument("--learning-curve", type=int, nargs="*", default=[], metavar="GROUPS",
                        help="also retrain the chosen form on random subsets of this many training groups "
                             f"({CURVE_DRAWS} seeded draws each) and report validation (report.json)")
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
    payload, payload_source = transfer_payload(args.data, args.results)
    print(f"payload {payload} ({payload_source['recipe']})", flush=True)
    train = collect(parts["train_learn"], payload, "train")
    loops = collect(parts["train_loops"], payload, "train loops")
    val = collect(parts["validation_learn"], payload, "validation")
    val_loops = collect(parts["validation_loops"], payload, "validation loops")
    test = collect(parts["test"], payload, "test")
    base_name = f"{LEARNED_BASE} (no correction)"
    forms: dict[str, dict] = {base_name: {"validation": transfer_errors(val, payload, None),
                                          "validation_loops": transfer_errors(val_loops, payload, None)}}
    print(f"{base_name}: {json.dumps(forms[base_name])}", flush=True)
    fee_plans = cold_plans("fee")
    (args.out / "forms").mkdir(parents=True, exist_ok=True)
    print(f"fee's cold plans: {json.dumps(fee_plans)}", flush=True)
    models = {}
    for name, form in FORMS.items():
        x, r, w = stack(train, loops=loops, loop_share=form.share)
        # the network with the build's payload (what the planner's "fee-learned" keeps; without it, its default)
        m = with_payload(form.train(x, r, w), payload)
        models[name] = m
        m.save(args.out / "forms" / f"form{len(models) - 1}.json")  # each form's network, to measure again
        rows = {"train": r2(m.correction(x), r)}
        for label, groups in (("validation", val), *((TEST_ROWS[g["group"]], [g]) for g in test)):
            gx, gr, _ = stack(groups, ("cross",))
            rows[label] = r2(m.correction(gx), gr) if gx is not None else None
        forms[name] = {"r2_tangential_normal_transfer": rows, "training_samples": int(len(x)),
                       "validation": transfer_errors(val, payload, m, CALIBRATION_PASSES),
                       "planner": cold_plans("fee-learned", m)}
        forms[name]["plannable"] = plannable(form, forms[name]["planner"], fee_plans)
        print(f"{name}: {json.dumps(forms[name])}", flush=True)
    # the planner carries the shipped network (one model everywhere), so a form it cannot plan with is reported,
    # never shipped (plannable: no kept-fill input, every cold plan solved and checked, no more IPOPT iterations
    # than the FEE's); among the rest, validation decides (docs/results/learned.md, "v7", the rule stated first)
    eligible = [k for k in FORMS if forms[k]["plannable"]]
    if not eligible:  # the side-by-side is the result: no weights are written (the shipped ones stay)
        write_report(args.out, {"forms": forms, "chosen": None, "beats_base_on_validation": None,
                                "fee_cold_plans": fee_plans, "learning_curve": []}, argv, t0)
        print(f"no form passes the planner gate: no weights written; the forms compared in {args.out}", flush=True)
        return 0
    chosen = min(eligible, key=lambda k: forms[k]["validation"]["one_cycle"])
    beats_base = forms[chosen]["validation"]["one_cycle"] < forms[base_name]["validation"]["one_cycle"]
    model = models[chosen]
    forms[chosen]["validation_loops"] = transfer_errors(val_loops, payload, model, CALIBRATION_PASSES)
    print(f"chosen {chosen} (beats the base on validation: {beats_base}): validation loops "
          f"{json.dumps(forms[chosen]['validation_loops'])}", flush=True)
    form = FORMS[chosen]
    manifest = {"version": VERSION, "command": COMMAND, "base": LEARNED_BASE,
                "form": f"{chosen}: tanh, mean of {ENSEMBLE} seeds, {form.hidden} hidden units a seed, L2 {form.l2}, "
                        f"smoothness penalty: slope {form.slope}, curvature {form.curvature}, box {form.box} "
                        f"(jitter {JITTER}), seeds {form.seed}-{form.seed + ENSEMBLE - 1}, "
                        f"{MAX_ITER} L-BFGS iterations, loop cycles {form.share} of the training weight, inputs left "
                        f"out: {', '.join(form.drop) or 'none'}, gated by the contact smoothstep",
                "chosen_by": "the lower median F_R RMSE from one cycle on the data/learn validation groups (forms) "
                             "among the forms the planner can carry (plannable: no kept-fill input, its cold plans "
                             f"on {', '.join(PLAN_SOILS)} all solved and passing the check, their median IPOPT "
                             "iterations at most the FEE's)", "beats_base_on_validation": beats_base,
                "inputs": list(INPUT_NAMES), "trusted_range": {"low": model.low.tolist(), "high": model.high.tolist()},
                "payload": payload.to_dict(), "payload_source": payload_source, "split": parts,
                "one_cycle_soils": {g["group"]: g["soils"] for g in train + loops + val + val_loops + test},
                "training_samples": forms[chosen]["training_samples"], "forms": forms, "sigma_s": SIGMA,
                "stride": STRIDE, "cross": CROSS}
    model = LearnedModel(model.w1, model.b1, model.w2, model.b2, model.mean, model.std, model.low, model.high,
                         version=VERSION, manifest=manifest)
    model.save(args.out / "fee-learned.json")
    (args.out / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    curve = learning_curve(train, loops, form, val, payload, args.learning_curve)
    report = write_report(args.out, {"forms": forms, "chosen": chosen, "beats_base_on_validation": beats_base,
                                     "fee_cold_plans": fee_plans, "learning_curve": curve}, argv, t0)
    print(f"wrote {args.out} ({chosen}) in {report['cpu_s']:.0f} s CPU", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
