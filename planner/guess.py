"""Where the optimiser starts: the pile's face ahead of the start and a straight-dig initial guess."""

from __future__ import annotations

import math

import numpy as np

from wheelloader.estimator import Bucket, BucketPath, Pile

from .options import StartState

__all__ = ["face_position", "first_rise", "straight_dig"]


def first_rise(pile: Pile, start: StartState, rise: float, step: float = 0.005, reach: float = 4.0) -> float | None:
    """x where the surface first lies more than ``rise`` above the start height, searching ``reach`` metres
    ahead of ``start`` in ``step`` increments [m]; None when it never does."""
    xs = start.x + np.arange(0.0, reach, step)
    rising = np.nonzero(np.asarray(pile.surface_height(xs)) > start.z + rise)[0]
    return float(xs[rising[0]]) if rising.size else None


def face_position(pile: Pile, start: StartState) -> float:
    """x where the surface first rises 3 cm above the start height ahead of ``start`` [m] (the face)."""
    x_face = first_rise(pile, start, 0.03)
    return start.x if x_face is None else x_face


def straight_dig(pile: Pile, start: StartState, duration: float, bucket: Bucket) -> BucketPath:
    """A simple initial guess: approach the face at ground level, dig ~15 cm under the surface, rise out.

    The approach ends where the surface first rises 5 cm above the start height; the dig
    advances until the bucket would be full (by carving), then the tip rises out of the pile.
    """
    x_face = first_rise(pile, start, 0.05)
    x_face = start.x + 0.5 if x_face is None else x_face
    depth = 0.15
    x_dig = np.linspace(x_face, x_face + 3.0, 301)
    z_dig = np.maximum(np.asarray(pile.surface_height(x_dig)) - depth, start.z)
    carve = pile.carve(np.concatenate([[start.x], x_dig]), np.concatenate([[start.z], z_dig]), bucket.width,
                       bucket.capacity, min(start.fill, bucket.capacity))
    full = np.nonzero(carve.fill_history[1:] >= 0.95 * bucket.capacity)[0]
    end = int(full[0]) if full.size else len(x_dig) - 1
    x_end = x_dig[end]
    z_top = float(pile.surface_height(x_end + 0.3)) + 0.1
    px = np.array([start.x, x_face, x_end, x_end + 0.3])
    pz = np.array([start.z, z_dig[0], z_dig[end], z_top])
    seg = np.hypot(np.diff(px), np.diff(pz))
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, duration, 121)
    s = t / duration * arc[-1]
    theta = np.interp(t / duration, [0.0, 0.6, 1.0], [start.blade_angle, start.blade_angle, math.radians(30.0)])
    return BucketPath(t, np.interp(s, arc, px), np.interp(s, arc, pz), theta, name="straight dig")
