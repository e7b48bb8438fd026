"""The learned correction of ``force_model="fee-learned"``: its base plus a small network learned from MPM.

The model (issue #32)::

    F_T, F_N = FEE_base(soil; state) + g(d) s MLP(x),       s = gamma g w L^2

where ``FEE_base`` is :data:`~wheelloader.estimator.force_models.LEARNED_BASE` (``"fee-payload-depth"`` from
weights v3, ``"fee-payload"`` before: the paper's eqs 1-17 with the payload state,
:mod:`~wheelloader.estimator.payload`, and N_gamma + k in eq 1), ``gamma`` the soil's density, ``w`` the bucket
width, ``L`` its floor length, and ``x`` the dimensionless inputs :data:`INPUT_NAMES`: the contact geometry (depth
/ L, the contact ramp, the blade angle to the surface rho, the slope alpha, the blade angle, the carved and the
kept fill as fractions of the nominal capacity, the Froude number of the tip speed) and the soil (tan phi, tan
delta, c / (gamma g L), c_a / (gamma g L)). ``g(d)`` is the contact gate :func:`contact_gate`: the smoothstep of
the depth over :data:`CONTACT_DEPTH` (C1, exactly 0 at and above the surface, 1 from 2 cm deep), so the correction
is exactly zero out of the soil (before entry, in the air, after exit: the payload model carries the load there).

The soil inputs are the soil a one-cycle calibration of the base finds, not the true soil: the network is
trained on the residual of each training cycle's own path and of other paths of its family at the soil fitted
to one cycle (``benchmarks/fee_learned.py``). So :func:`~wheelloader.estimator.calibration.calibrate` starts
from the base's own fit, refits it once to the forces less the correction at that soil
(:data:`CALIBRATION_PASSES`), and the prediction adds the correction at the soil found, near where it was
trained.

The network is one ``tanh`` hidden layer on standardised inputs, each input clipped to its training range
first (:attr:`LearnedModel.low`, :attr:`LearnedModel.high`, the 0.5th and 99.5th percentiles of the training
samples): outside it the correction stays at the range's edge and :func:`learned_forces` flags the sample
(:attr:`LearnedForces.outside`). Prediction needs NumPy only; :func:`casadi_correction` is the same network in
CasADi symbols (exact gradients; the planner's twin), tested to agree with :meth:`LearnedModel.correction`.

The weights are a shipped, versioned artifact (:data:`DEFAULT_ARTIFACT`, with the training split in its
``manifest``), built by ``python benchmarks/fee_learned.py --out estimator/learned_weights`` (NumPy + SciPy,
no extra dependency). ``docs/guide/learned.md`` says what it was trained on and where not to trust it.
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .cyclelog import CycleLog
from .errors import ParameterError
from .force_model import GRAVITY
from .force_models import DEFAULT_PAYLOAD
from .kinematics import DEFAULT_SLOPE_WINDOW, ContactState
from .machine import Bucket
from .paths import BucketPath
from .payload import PayloadOptions, payload_contact_state
from .soil import SoilParams

__all__ = ["CALIBRATION_PASSES", "CONTACT_DEPTH", "DEFAULT_ARTIFACT", "FORMAT", "INPUT_NAMES", "LearnedForces",
           "LearnedModel", "casadi_correction", "contact_gate", "corrected_log", "default_learned_model", "force_scale",
           "learned_forces", "learned_inputs"]

#: Names of the network's inputs, in order.
INPUT_NAMES: tuple[str, ...] = ("depth_over_length", "contact_ramp", "rho", "alpha", "blade_angle",
                                "carved_fill_fraction", "kept_fill_fraction", "froude", "tan_phi", "tan_delta",
                                "cohesion_number", "adhesion_number")
#: Depth over which the contact ramp goes from 0 to 1 [m].
CONTACT_DEPTH = 0.02
#: Fixed-point passes of the calibration (fit the FEE to the forces minus the correction at the current soil).
#: 1: the correction is trained at the soil a plain ``fee-payload`` fit of one cycle finds (module docstring); one
#: pass refits the FEE to the forces less the correction there (a log of the fee-learned env then recovers a
#: converged fit; with 0 passes its plain fit ran out of evaluations).
CALIBRATION_PASSES = 1
FORMAT = "wheelloader.fee-learned"
#: The shipped weights (package data).
DEFAULT_ARTIFACT = Path(__file__).with_name("learned_weights") / "fee-learned.json"


def contact_gate(ramp: np.ndarray) -> np.ndarray:
    """The correction's gate from the contact ramp ``depth / CONTACT_DEPTH`` (any real): the smoothstep
    ``t^2 (3 - 2 t)`` of ``t = clip(ramp, 0, 1)``; C1, exactly 0 at and above the surface, 1 from
    :data:`CONTACT_DEPTH` deep."""
    t = np.clip(ramp, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def force_scale(gamma: float, bucket: Bucket) -> float:
    """``s = gamma g w L^2`` [N]."""
    return float(gamma) * GRAVITY * bucket.width * bucket.floor_length ** 2


def learned_inputs(state: ContactState, path: BucketPath, bucket: Bucket, soil: SoilParams) -> np.ndarray:
    """The network's inputs (samples x :data:`INPUT_NAMES`) along a path.

    ``state`` is the payload model's contact state (its ``carried_volume`` the kept soil).
    """
    length = bucket.floor_length
    depth = np.maximum(np.asarray(state.depth, float), 0.0)
    kept = state.fill_volume if state.carried_volume is None else state.carried_volume
    vx, vz, _ = path.velocity()
    n = depth.size
    weight = soil.gamma * GRAVITY * length
    soil_cols = np.tile([math.tan(soil.phi), math.tan(soil.delta), soil.cohesion / weight, soil.adhesion / weight],
                        (n, 1))
    return np.column_stack([depth / length, np.minimum(depth / CONTACT_DEPTH, 1.0), state.rho, state.alpha,
                            path.blade_angle, np.asarray(state.fill_volume) / bucket.capacity,
                            np.asarray(kept) / bucket.capacity, np.hypot(vx, vz) / math.sqrt(GRAVITY * length),
                            soil_cols])


@dataclass(frozen=True, eq=False)
class LearnedModel:
    """The network's weights, standardisation and trusted input range.

    Attributes
    ----------
    w1 : numpy.ndarray
        (inputs x hidden) first-layer weights; ``b1`` (hidden,) its biases.
    w2 : numpy.ndarray
        (hidden x 2) output weights; ``b2`` (2,) its biases (outputs: F_T and F_N corrections over ``s``).
    mean, std : numpy.ndarray
        Standardisation of the inputs.
    low, high : numpy.ndarray
        The trusted input range (inputs are clipped to it; outside it a sample is flagged).
    version : str
        Artifact version.
    manifest : dict
        What it was trained on (split by case family), the command that built it, its held-out figures.
    """

    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    low: np.ndarray
    high: np.ndarray
    version: str = "unversioned"
    manifest: dict[str, Any] | None = None

    def __post_init__(self) -> None:
        m = len(INPUT_NAMES)
        hidden = np.shape(self.w1)[1] if np.ndim(self.w1) == 2 else -1
        shapes = {"w1": (m, hidden), "b1": (hidden,), "w2": (hidden, 2), "b2": (2,), "mean": (m,), "std": (m,),
                  "low": (m,), "high": (m,)}
        for name, shape in shapes.items():
            value = getattr(self, name)
            if hidden < 1 or np.shape(value) != shape or not np.all(np.isfinite(value)):
                raise ParameterError(f"learned model: {name} must be a finite array of shape {shape}")
        if np.any(np.asarray(self.std) <= 0.0) or np.any(np.asarray(self.low) > np.asarray(self.high)):
            raise ParameterError("learned model: std must be positive and low <= high")

    @property
    def hidden(self) -> int:
        return int(np.shape(self.w1)[1])

    @property
    def payload(self) -> PayloadOptions:
        """The payload fitted with the correction (the manifest's; :data:`DEFAULT_PAYLOAD` when it has none)."""
        stored = (self.manifest or {}).get("payload")
        return DEFAULT_PAYLOAD if stored is None else PayloadOptions(**stored)

    def correction(self, x: np.ndarray) -> np.ndarray:
        """Dimensionless corrections (samples x 2: F_T, F_N over ``s``) at inputs ``x`` (samples x inputs), gated
        by :func:`contact_gate` of the contact ramp (input 1): exactly 0 out of the soil."""
        return contact_gate(x[:, 1])[:, None] * self.ungated(x)

    def ungated(self, x: np.ndarray) -> np.ndarray:
        """The network alone (no gate): inputs clipped to the trusted range, standardised, two layers."""
        z = (np.clip(x, self.low, self.high) - self.mean) / self.std
        return np.tanh(z @ self.w1 + self.b1) @ self.w2 + self.b2

    def outside(self, x: np.ndarray) -> np.ndarray:
        """True where a sample's inputs leave the trusted range."""
        return np.any((x < self.low) | (x > self.high), axis=1)

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (the artifact)."""
        return {"format": FORMAT, "version": self.version, "inputs": list(INPUT_NAMES),
                **{k: np.asarray(getattr(self, k)).tolist() for k in ("w1", "b1", "w2", "b2", "mean", "std", "low",
                                                                      "high")},
                "manifest": self.manifest or {}}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LearnedModel:
        """Inverse of :meth:`to_dict`."""
        if data.get("format") != FORMAT:
            raise ParameterError(f"learned model: format must be {FORMAT!r}, got {data.get('format')!r}")
        if list(data.get("inputs", [])) != list(INPUT_NAMES):
            raise ParameterError(f"learned model: inputs must be {list(INPUT_NAMES)}")
        arrays = {k: np.asarray(data[k], dtype=float) for k in ("w1", "b1", "w2", "b2", "mean", "std", "low", "high")}
        return cls(**arrays, version=str(data.get("version", "unversioned")), manifest=data.get("manifest"))

    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), separators=(",", ":")) + "\n")
        return path

    @classmethod
    def load(cls, path: str | Path) -> LearnedModel:
        return cls.from_dict(json.loads(Path(path).read_text()))


@functools.lru_cache(maxsize=1)
def default_learned_model() -> LearnedModel:
    """The shipped weights (:data:`DEFAULT_ARTIFACT`)."""
    if not DEFAULT_ARTIFACT.exists():
        raise ParameterError(f"the learned model's weights are missing ({DEFAULT_ARTIFACT}); build them with "
                             "python benchmarks/fee_learned.py --out estimator/learned_weights")
    return LearnedModel.load(DEFAULT_ARTIFACT)


@dataclass(frozen=True, eq=False)
class LearnedForces:
    """The correction along a path: ``tangential``, ``normal`` [N]; ``outside``: samples whose inputs leave
    the training range (per sample, bool)."""

    tangential: np.ndarray
    normal: np.ndarray
    outside: np.ndarray


def learned_forces(model: LearnedModel, state: ContactState, path: BucketPath, bucket: Bucket,
                   soil: SoilParams) -> LearnedForces:
    """The correction ``s * MLP(x)`` [N] along a path (module docstring)."""
    x = learned_inputs(state, path, bucket, soil)
    r = model.correction(x) * force_scale(soil.gamma, bucket)
    return LearnedForces(r[:, 0], r[:, 1], model.outside(x))


def corrected_log(model: LearnedModel, log: CycleLog, soil: SoilParams, payload: PayloadOptions,
                  slope_window: float = DEFAULT_SLOPE_WINDOW) -> tuple[CycleLog, LearnedForces]:
    """The log with the correction at ``soil`` taken off its forces (what the FEE is fitted to), and the correction."""
    state = payload_contact_state(log, payload, slope_window)
    lf = learned_forces(model, state, log.path, log.bucket, soil)
    return replace(log, tangential=log.tangential - lf.tangential, normal=log.normal - lf.normal), lf


def casadi_correction(model: LearnedModel, x: Any) -> Any:
    """The network in CasADi symbols: ``x`` a (1 x inputs) row (SX/MX/DM) -> (1 x 2) corrections over ``s``.

    The same clip, standardisation, layers and gate as :meth:`LearnedModel.correction` (the planner's twin; the
    gate's smoothstep of the clipped ramp is C1, so its derivatives are continuous at the surface).
    """
    import casadi as ca

    lo, hi = ca.DM(model.low).T, ca.DM(model.high).T
    z = (ca.fmin(ca.fmax(x, lo), hi) - ca.DM(model.mean).T) / ca.DM(model.std).T
    h = ca.tanh(ca.mtimes(z, ca.DM(model.w1)) + ca.DM(model.b1).T)
    t = ca.fmin(ca.fmax(x[:, 1], 0.0), 1.0)
    return (t * t * (3.0 - 2.0 * t)) * (ca.mtimes(h, ca.DM(model.w2)) + ca.DM(model.b2).T)
