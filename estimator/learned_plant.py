"""The learned correction of ``force_model="fee-learned"`` at one soil: a sample at a time (the env) or rows.

:func:`~wheelloader.estimator.learned.learned_forces` evaluates the correction along a whole path from a contact
state. The env needs it one sample per step, at a cost that keeps the step within twice the FEE's. This is the
same network (:meth:`~wheelloader.estimator.learned.LearnedModel.correction`), with its standardisation folded
into the first layer and the soil's inputs (constant over an episode) folded into its biases::

    W1' = W1 / std,   b1' = b1 - (mean / std) W1 + clip(x_soil) W1'_soil,   F = g s (tanh(clip(x) W1' + b1') W2 + b2)

with ``x`` the contact inputs of :data:`~wheelloader.estimator.learned.INPUT_NAMES` (depth / L, the contact ramp,
rho, alpha, the blade angle, the carved and kept fill fractions, the Froude number of the tip speed) and
``s = gamma g w L^2``, ``g`` the contact gate (:func:`~wheelloader.estimator.learned.contact_gate`: exactly 0 out
of the soil, where :meth:`LearnedCorrection.single` returns at once). The two agree to rounding
(``tests/test_force_model_everywhere.py``).
"""

from __future__ import annotations

import math

import numpy as np

from .force_model import GRAVITY
from .learned import CONTACT_DEPTH, LearnedModel, contact_gate, default_learned_model, force_scale
from .machine import Bucket
from .soil import SoilParams

__all__ = ["CONTACT_INPUTS", "LearnedCorrection", "learned_correction"]

#: The inputs that change along a path (the first of ``INPUT_NAMES``); the rest are the soil's.
CONTACT_INPUTS = 8


class LearnedCorrection:
    """The learned correction at one soil and bucket (module docstring).

    Parameters
    ----------
    model : LearnedModel
        The network (weights, standardisation, trusted range).
    soil : SoilParams
        The soil (its inputs and the force scale).
    bucket : Bucket
        Floor length, width and capacity.
    """

    def __init__(self, model: LearnedModel, soil: SoilParams, bucket: Bucket) -> None:
        m = CONTACT_INPUTS
        w1 = np.asarray(model.w1) / np.asarray(model.std)[:, None]
        b1 = np.asarray(model.b1) - (np.asarray(model.mean) / np.asarray(model.std)) @ np.asarray(model.w1)
        length = bucket.floor_length
        weight = soil.gamma * GRAVITY * length
        x_soil = np.array([math.tan(soil.phi), math.tan(soil.delta), soil.cohesion / weight, soil.adhesion / weight])
        self.soil_outside = bool(np.any((x_soil < model.low[m:]) | (x_soil > model.high[m:])))
        b1 = b1 + np.clip(x_soil, model.low[m:], model.high[m:]) @ w1[m:]
        scale = force_scale(soil.gamma, bucket)
        self._w1, self._b1 = np.ascontiguousarray(w1[:m]), b1
        self._w2, self._b2 = np.asarray(model.w2) * scale, np.asarray(model.b2) * scale
        self._low, self._high = np.asarray(model.low[:m], float), np.asarray(model.high[:m], float)
        self._inv_length = 1.0 / length
        self._inv_capacity = 1.0 / bucket.capacity
        self._inv_froude = 1.0 / math.sqrt(GRAVITY * length)
        self._x = np.empty(m)
        self._h = np.empty(model.hidden)

    def single(self, depth: float, rho: float, alpha: float, blade_angle: float, carved: float, kept: float,
               speed: float) -> tuple[float, float]:
        """The correction ``(F_T, F_N)`` [N] at one sample (depth [m], angles [rad], fills [m^3], speed [m/s])."""
        if depth <= 0.0:  # the gate: exactly 0 out of the soil
            return 0.0, 0.0
        ramp = depth / CONTACT_DEPTH
        if ramp > 1.0:
            ramp = gate = 1.0
        else:
            gate = ramp * ramp * (3.0 - 2.0 * ramp)
        x = self._x
        x[:] = (depth * self._inv_length, ramp, rho, alpha, blade_angle, carved * self._inv_capacity,
                kept * self._inv_capacity, speed * self._inv_froude)
        np.maximum(x, self._low, out=x)
        np.minimum(x, self._high, out=x)
        h = np.dot(x, self._w1, out=self._h)
        h += self._b1
        np.tanh(h, out=h)
        f_t, f_n = (h @ self._w2 + self._b2).tolist()
        return gate * f_t, gate * f_n

    def inputs(self, depth, rho, alpha, blade_angle, carved, kept, speed) -> np.ndarray:
        """The contact inputs (rows x :data:`CONTACT_INPUTS`), not clipped."""
        d = np.maximum(np.asarray(depth, float), 0.0)
        return np.column_stack([d * self._inv_length, np.minimum(d / CONTACT_DEPTH, 1.0), rho, alpha, blade_angle,
                                np.asarray(carved) * self._inv_capacity, np.asarray(kept) * self._inv_capacity,
                                np.asarray(speed) * self._inv_froude])

    def rows(self, depth, rho, alpha, blade_angle, carved, kept, speed) -> tuple[np.ndarray, np.ndarray]:
        """The correction ``(F_T, F_N)`` [N] at many samples (arrays as in :meth:`single`)."""
        x = self.inputs(depth, rho, alpha, blade_angle, carved, kept, speed)
        gate = contact_gate(x[:, 1])[:, None]
        x = np.clip(x, self._low, self._high)
        r = gate * (np.tanh(x @ self._w1 + self._b1) @ self._w2 + self._b2)
        return r[:, 0], r[:, 1]

    def outside(self, depth, rho, alpha, blade_angle, carved, kept, speed) -> np.ndarray:
        """True where a sample's inputs (or the soil's) leave the trusted range."""
        x = self.inputs(depth, rho, alpha, blade_angle, carved, kept, speed)
        return np.any((x < self._low) | (x > self._high), axis=1) | self.soil_outside


def learned_correction(soil: SoilParams, bucket: Bucket, model: LearnedModel | None = None) -> LearnedCorrection:
    """The shipped correction (:func:`~wheelloader.estimator.learned.default_learned_model`) at ``soil``."""
    return LearnedCorrection(default_learned_model() if model is None else model, soil, bucket)
