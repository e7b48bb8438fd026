"""Where the optimiser starts: the pile's face ahead of the start and a straight-dig initial guess."""

from __future__ import annotations

import math

import numpy as np

from wheelloader.estimator import DEFAULT_OPTIONS, DEFAULT_SLOPE_WINDOW, Bucket, BucketPath, Pile
from wheelloader.estimator.validity import alpha_lower_limit

from .options import StartState

__all__ = ["DIG_DEPTHS", "diggable", "face_position", "first_rise", "straight_dig", "surface_dig"]


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


#: Depths below the surface [m] tried by :func:`surface_dig` (shallow first).
DIG_DEPTHS = (0.12, 0.18, 0.25)


def diggable(pile: Pile, x: np.ndarray, phi: float, margin: float) -> np.ndarray:
    """Where a tip in soil stays inside the model's slope domain: the chord slope at ``x`` within
    ``[alpha_lower_limit(phi) + margin, alpha_max - margin]`` (boolean array)."""
    alpha = np.asarray(pile.slope_angle(x, DEFAULT_SLOPE_WINDOW), dtype=float)
    lo = float(alpha_lower_limit(phi, DEFAULT_OPTIONS)) + margin
    return (alpha >= lo) & (alpha <= DEFAULT_OPTIONS.alpha_max - margin)


def surface_dig(pile: Pile, start: StartState, duration: float, bucket: Bucket, phi: float,
                margin: float = math.radians(5.0), fill_target: float = 0.85, rho: float = math.radians(30.0),
                clearance: float = 0.04, step: float = 0.01, reach: float = 3.0) -> tuple[BucketPath, float]:
    """A validity-aware initial guess on a (carved) pile: over the air to where the slope lets the tip dig,
    then at a constant depth below the surface until the bucket is full, then out.

    The dig stretch is the first one past the face where the surface slope stays inside the model's domain
    (:func:`diggable`) until ``fill_target`` of the capacity is carved at one of :data:`DIG_DEPTHS`, so
    the tip passes steep carved walls and down-slopes the model cannot describe in the air, before it has
    loaded soil (the env lets it). The blade is held at ``rho`` to the local surface while digging.
    Geometry and carving only (no force model). Returns ``(path, entry)``, ``entry`` the x where the dig
    starts [m] (the NLP's face); when no stretch reaches the target the one that fills most is used.
    """
    x_face = first_rise(pile, start, 0.05)
    x_face = start.x + 0.5 if x_face is None else x_face
    xs = np.arange(max(start.x + 0.05, x_face - 0.1), x_face + reach, step)
    surf = np.asarray(pile.surface_height(xs), dtype=float)
    ok = diggable(pile, xs, phi, margin) & (surf > start.z + 0.03)
    target = fill_target * bucket.capacity
    z_floor = min(float(pile.heights.min()), start.z)
    best: tuple[float, int, int, float] | None = None  # (fill, entry index, exit index, depth)
    i = 0
    while i < xs.size:
        if not ok[i]:
            i += 1
            continue
        j = i
        while j + 1 < xs.size and ok[j + 1]:
            j += 1
        for depth in DIG_DEPTHS:
            ramp = np.clip((xs[i:j + 1] - xs[i]) / max(depth, 0.05), 0.0, 1.0)
            z = np.maximum(surf[i:j + 1] - depth * ramp, z_floor)
            fill = pile.carve(xs[i:j + 1], z, bucket.width, bucket.capacity).fill_history
            full = np.nonzero(fill >= target)[0]
            end = int(full[0]) if full.size else j - i
            if best is None or min(fill[end], target) > best[0] + 1e-9:
                best = (min(float(fill[end]), target), i, i + end, depth)
            if full.size:
                break
        if best is not None and best[0] >= target - 1e-9:
            break
        i = j + 1
    if best is None:
        return straight_dig(pile, start, duration, bucket), x_face
    _, i, j, depth = best
    x_dig = xs[i:j + 1]
    ramp = np.clip((x_dig - x_dig[0]) / max(depth, 0.05), 0.0, 1.0)
    z_dig = np.maximum(surf[i:j + 1] - depth * ramp, z_floor)
    alpha = np.asarray(pile.slope_angle(x_dig, DEFAULT_SLOPE_WINDOW), dtype=float)
    th_dig = np.convolve(np.pad(alpha, 5, mode="edge"), np.ones(11) / 11.0, mode="valid") - rho
    # the approach: a straight line from the start, lifted to stay clear of the surface until the entry
    x_app = np.arange(start.x, x_dig[0], step)
    line = start.z + (x_app - start.x) / max(x_dig[0] - start.x, 1e-9) * (z_dig[0] - start.z)
    lift = clearance * np.clip((x_dig[0] - x_app) / 0.1, 0.0, 1.0)
    z_app = np.maximum(line, np.asarray(pile.surface_height(x_app), dtype=float) + lift)
    z_app[0] = start.z
    x_end = float(x_dig[-1])
    z_top = float(pile.surface_height(x_end + 0.1)) + 0.1
    px = np.concatenate([x_app, x_dig, [x_end + 0.02, x_end + 0.1]])
    pz = np.concatenate([z_app, z_dig, [0.5 * (z_dig[-1] + z_top), z_top]])
    pth = np.concatenate([np.linspace(start.blade_angle, th_dig[0], x_app.size), th_dig,
                          [th_dig[-1], math.radians(30.0)]])
    seg = np.hypot(np.diff(px), np.diff(pz))
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    t = arc / arc[-1] * duration
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    return BucketPath(t[keep], px[keep], pz[keep], pth[keep], name="surface dig"), float(x_dig[0])
