"""Fallback paths when a plan fails its check: the default Bezier path placed on the current face.

:func:`bezier_on_face` places it geometrically (where it fills the bucket, as an operator would re-use
a standard path); :func:`model_bezier_on_face` moves it to where a soil's force model predicts the least
energy per m^3 at the same fill. The cycle-to-cycle loop digs one of them when the optimiser's plan fails.
"""

from __future__ import annotations

import math

import numpy as np

from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    Bucket,
    BucketPath,
    Loader,
    ModelOptions,
    PayloadOptions,
    Pile,
    SoilParams,
    default_path,
)
from wheelloader.estimator.quantise import better, quantise_pile, quantise_soil

from .verify import cycle_end_index, path_energy

#: The end-of-cycle rule these placements assume: the cycle ends on the first exit after loading 5 % of
#: the bucket (the env's ``exit_min_fill`` as the cycle-to-cycle loop sets it).
LOOP_EXIT_MIN_FILL = 0.05
MODEL_FALLBACK_NAME = "Bezier, model-placed"
"""Name of the path :func:`model_bezier_on_face` returns: the loop digs it where a plan fails its check."""


def bezier_on_face(pile: Pile, rate: float = 60.0, bucket: Bucket | None = None, step: float = 0.02,
                   max_shift: float = 3.0, exit_min_fill: float = LOOP_EXIT_MIN_FILL) -> BucketPath:
    """The default Bezier path slid along +x to the first place where it would fill the bucket.

    The target is the fill the path reaches on the fresh default pile (89 %
    of the default bucket); the search is geometric (carving only, no force
    model), in ``step`` increments up to ``max_shift`` metres, and counts the
    fill the env would let the path keep: up to where the env would end the
    cycle (:func:`~wheelloader.planner.verify.cycle_end_index`, the loop's
    rule: the first exit 2 cm above the surface after loading ``exit_min_fill``, 5 % by default). This is how an
    operator would re-use a standard path on a carved pile: the fixed
    baseline is positioned fairly, not left digging air or skimming a hump. The search runs on the pile
    rounded to :data:`~wheelloader.estimator.quantise.PILE_STEP` (last-bit differences do not move it).
    """
    bucket = Bucket() if bucket is None else bucket
    pile = quantise_pile(pile)
    path = default_path(rate=rate)
    target = Pile.trapezoid().carve(path.x, path.z, bucket.width, bucket.capacity).in_bucket
    best, best_fill = 0.0, -1.0
    for dx in np.arange(0.0, max_shift + 1e-9, step):
        fill, _ = _kept(pile, path.x + dx, path.z, bucket, exit_min_fill)
        if fill > best_fill + 1e-12:
            best, best_fill = float(dx), fill
        if fill >= 0.98 * target:
            best = float(dx)
            break
    return path.shifted(dx=best, name="Bezier")


def _kept(pile: Pile, x: np.ndarray, z: np.ndarray, bucket: Bucket,
          exit_min_fill: float = LOOP_EXIT_MIN_FILL) -> tuple[float, int]:
    """``(fill [m^3], index of the last sample)`` of a path up to where the env would end its cycle
    (the first exit after loading ``exit_min_fill`` of the bucket, else the path's end)."""
    fill = pile.carve(x, z, bucket.width, bucket.capacity).fill_history
    clearance = z - np.asarray(pile.surface_height(x))
    end = cycle_end_index(clearance < 0.0, clearance, fill / bucket.capacity, exit_min_fill=exit_min_fill, z=z,
                          crest=float(np.max(pile.heights)))
    end = len(x) - 1 if end is None else end
    return float(fill[end]), end


#: Offsets [m] of the default Bezier path tried by :func:`model_bezier_on_face`: along x around the geometric
#: placement, and along z (negative: deeper).
MODEL_SHIFTS = (-0.10, -0.05, 0.0, 0.05, 0.10, 0.15, 0.20)
MODEL_LIFTS = (0.04, 0.0, -0.04, -0.08)


def model_bezier_on_face(soil: SoilParams, pile: Pile, rate: float = 60.0, bucket: Bucket | None = None,
                         loader: Loader | None = None, exit_min_fill: float = LOOP_EXIT_MIN_FILL,
                         model_options: ModelOptions = DEFAULT_OPTIONS,
                         payload: PayloadOptions | None = None, learned: bool = False) -> BucketPath:
    """The default Bezier path moved to where ``soil``'s force model predicts the least energy per m^3.

    Starts from :func:`bezier_on_face` (geometric placement) and tries it
    moved by :data:`MODEL_SHIFTS` along x and :data:`MODEL_LIFTS` along z.
    A candidate counts only if it keeps at least the geometric placement's
    fill (up to where the env would end the cycle) and the predicted forces
    stay within the loader's limits (no stall); among those, the least
    predicted energy per m^3 (the NumPy model with ``soil``: calibrated
    parameters make this choice better) wins. The fallback of the
    calibrating strategies when a plan fails its check; up to 28 model
    evaluations. ``model_options``: the force model's (the planner's failure-angle rule); ``payload``: its
    payload under the payload models (the carried load; the fill the candidates must keep stays the carving's);
    ``learned``: ``"fee-learned"``'s correction on top (:func:`~wheelloader.planner.verify.path_energy`).

    Like the planner, it decides on ``soil`` and ``pile`` rounded to fixed grids
    (:mod:`wheelloader.estimator.quantise`), and a later candidate wins only when it is cheaper by more
    than :data:`~wheelloader.estimator.quantise.TIE_RELATIVE` (on a near-tie the earlier in the fixed
    order of :data:`MODEL_SHIFTS` x :data:`MODEL_LIFTS` stays).
    """
    bucket = Bucket() if bucket is None else bucket
    loader = Loader() if loader is None else loader
    soil, pile = quantise_soil(soil), quantise_pile(pile)
    base = bezier_on_face(pile, rate, bucket, exit_min_fill=exit_min_fill)
    need = 0.98 * _kept(pile, base.x, base.z, bucket, exit_min_fill)[0]
    best, best_cost = base, math.inf
    for dx in MODEL_SHIFTS:
        for dz in MODEL_LIFTS:
            path = base.shifted(dx=dx, dz=dz)
            fill, end = _kept(pile, path.x, path.z, bucket, exit_min_fill)
            if fill < need or fill <= 0.0:
                continue
            part = BucketPath(path.t[:end + 1], path.x[:end + 1], path.z[:end + 1], path.blade_angle[:end + 1],
                              path.name)
            sim = path_energy(part, soil, pile, bucket, model_options=model_options, payload=payload, learned=learned)
            forces = sim["forces"]
            if forces.tangential.max() > loader.max_push_force or forces.normal.max() > loader.max_lift_force:
                continue
            cost = sim["energy"] / fill
            if better(cost, best_cost):
                best, best_cost = path, cost
    return best.shifted(name=MODEL_FALLBACK_NAME)
