"""Synthetic cycle logs with a known soil, for tests and benchmarks.

:func:`synthetic_cycle` runs the force model along a path on a pile and adds
measurement noise like a load-pin signal: white noise, a band-limited
vibration (default 5-15 Hz, the band of machine and hydraulic vibration) and
an optional constant bias. All noise amplitudes are fractions of the force
scale, the peak true resultant force of the cycle. The true forces and the
true soil are kept in the log's metadata.

:func:`random_soil` and :func:`random_bezier_path` draw random problems for
robustness checks.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .checks import check_finite, check_range
from .cyclelog import CycleLog
from .errors import ParameterError
from .force_model import DEFAULT_OPTIONS, ModelOptions, soil_forces
from .kinematics import contact_state
from .machine import Bucket
from .paths import BucketPath, bezier_path, default_path
from .pile import Pile
from .soil import PAPER_BOUNDS, PARAMETER_NAMES, SoilParams, as_soil

#: Default vibration band [Hz].
DEFAULT_BAND = (5.0, 15.0)


def band_limited_noise(rng: np.random.Generator, size: int, rate: float, band: tuple[float, float]) -> np.ndarray:
    """Zero-mean Gaussian noise with unit standard deviation and its power inside ``band`` [Hz].

    White noise is filtered in the frequency domain (all bins outside the
    band set to zero) and rescaled to unit sample standard deviation. The
    band is cut at the Nyquist frequency ``rate / 2``.
    """
    lo, hi = (float(v) for v in band)
    if not (0.0 <= lo < hi):
        raise ParameterError(f"vibration_band must be (low, high) with 0 <= low < high Hz, got {band!r}")
    spec = np.fft.rfft(rng.standard_normal(size))
    freq = np.fft.rfftfreq(size, d=1.0 / rate)
    spec[(freq < lo) | (freq > min(hi, 0.5 * rate))] = 0.0
    sig = np.fft.irfft(spec, n=size)
    std = float(np.std(sig))
    if std == 0.0:
        raise ParameterError(f"vibration_band {band!r} holds no frequency bin of a {size}-sample signal at {rate:g} Hz")
    return sig / std


def _pair(name: str, value: Any) -> tuple[float, float]:
    if np.ndim(value) == 0:
        v = float(value)
        pair = (v, v)
    else:
        vals = [float(v) for v in np.ravel(value)]
        if len(vals) != 2:
            raise ParameterError(f"{name} must be a number or a (tangential, normal) pair, got {value!r}")
        pair = (vals[0], vals[1])
    return check_finite(f"{name}[0]", pair[0]), check_finite(f"{name}[1]", pair[1])


def synthetic_cycle(
    soil: SoilParams | str | dict,
    path: BucketPath | None = None,
    pile: Pile | None = None,
    bucket: Bucket | None = None,
    *,
    noise: float = 0.05,
    vibration: float = 0.0,
    vibration_band: tuple[float, float] = DEFAULT_BAND,
    bias: float | tuple[float, float] = 0.0,
    seed: int | np.random.Generator | None = None,
    force_scale: float | None = None,
    options: ModelOptions = DEFAULT_OPTIONS,
) -> CycleLog:
    """A cycle log of the force model with a known soil and realistic noise.

    Parameters
    ----------
    soil : SoilParams, str or dict
        The true soil (a preset name is accepted).
    path : BucketPath, optional
        Tip path; default :func:`~wheelloader.estimator.paths.default_path`.
    pile : Pile, optional
        Surface at the start of the cycle; default ``Pile.trapezoid()``.
    bucket : Bucket, optional
        Default ``Bucket()``.
    noise : float
        Standard deviation of the white noise on F_T and on F_N, as a
        fraction of the force scale (default 0.05 = 5 %).
    vibration : float
        Standard deviation of the band-limited vibration, as a fraction of
        the force scale (default 0).
    vibration_band : tuple of float
        Vibration band [Hz] (default 5-15 Hz).
    bias : float or (float, float)
        Constant offset of (F_T, F_N) as a fraction of the force scale.
    seed : int or numpy.random.Generator, optional
        Randomness (explicit seeds make cycles reproducible).
    force_scale : float, optional
        Force scale [N]; default the peak true resultant of the cycle (1 kN
        if the path never enters the soil).
    options : ModelOptions
        Force-model options.

    Returns
    -------
    CycleLog
        With the logged bucket fill (from carving), the carved surface as
        ``pile_after`` and metadata ``{"source": "synthetic", "soil": {...},
        "noise": ..., "vibration": ..., "vibration_band": ..., "bias": ...,
        "seed": ..., "force_scale": ..., "true_tangential": [...],
        "true_normal": [...]}``.
    """
    soil = as_soil(soil)
    path = default_path() if path is None else path
    pile = Pile.trapezoid() if pile is None else pile
    bucket = Bucket() if bucket is None else bucket
    if not isinstance(path, BucketPath):
        raise ParameterError(f"path must be a BucketPath, got {type(path).__name__}")
    for name, value in (("noise", noise), ("vibration", vibration)):
        check_range(name, value, 0.0, None)  # a fraction of the peak force
    bias_t, bias_n = _pair("bias", bias)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    acceleration = np.column_stack(path.acceleration()) if options.carried_load else None
    velocity = np.column_stack(path.velocity()[:2]) if options.slip_friction else None
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket, acceleration=acceleration,
                          velocity=velocity)
    forces = soil_forces(soil, state, bucket, options)
    peak = float(np.max(forces.resultant))
    if force_scale is None:
        scale = peak if peak > 0.0 else 1000.0
    else:
        scale = check_range("force_scale", force_scale, 0.0, None, low_open=True)  # N
    n = len(path)
    rate = (n - 1) / path.duration
    measured = []
    for true, b in ((forces.tangential, bias_t), (forces.normal, bias_n)):
        sig = true + noise * scale * rng.standard_normal(n)
        if vibration > 0.0:
            sig = sig + vibration * scale * band_limited_noise(rng, n, rate, vibration_band)
        measured.append(sig + b * scale)
    metadata = {
        "source": "synthetic",
        "soil": soil.to_dict(),
        "noise": float(noise),
        "vibration": float(vibration),
        "vibration_band": [float(v) for v in vibration_band],
        "bias": [bias_t, bias_n],
        "seed": seed if isinstance(seed, int) else None,
        "force_scale": scale,
        "true_tangential": forces.tangential.tolist(),
        "true_normal": forces.normal.tolist(),
    }
    carve = state.carve
    return CycleLog(path, measured[0], measured[1], pile, bucket, fill_volume=carve.fill_history,
                    pile_after=carve.pile, metadata=metadata)


def random_soil(rng: np.random.Generator, bounds: dict[str, tuple[float, float]] | None = None,
                zero_probability: float = 0.25) -> SoilParams:
    """A random soil inside ``bounds`` (default the paper's).

    Every parameter is uniform in its bound, except: cohesion and adhesion
    are 0 with probability ``zero_probability`` each (cohesionless soils are
    common) and otherwise log-uniform in [100 Pa, upper]; ``k_c`` and
    ``k_phi`` are log-uniform over [1e-3, 1] of their upper bound (the
    literature values of Table A2 span decades).
    """
    b = dict(PAPER_BOUNDS if bounds is None else bounds)
    values = {name: rng.uniform(*b[name]) for name in PARAMETER_NAMES}
    for name in ("cohesion", "adhesion"):
        lo, hi = b[name]
        if rng.random() < zero_probability:
            values[name] = lo
        else:
            values[name] = float(np.exp(rng.uniform(math.log(max(lo, 100.0)), math.log(max(hi, 101.0)))))
    for name in ("k_c", "k_phi"):
        lo, hi = b[name]
        values[name] = float(np.clip(hi * np.exp(rng.uniform(math.log(1e-3), 0.0)), lo, hi))
    return SoilParams(**values)


def perturbed_preset(name: str, seed: int, spread: float = 0.1) -> SoilParams:
    """A hidden soil near the preset ``name``: gamma, cohesion, adhesion, phi, delta and k_c each scaled by
    ``exp(N(0, spread))`` (a log-normal perturbation, drawn from ``default_rng(1000 + seed)``) and clipped into
    the paper's bounds, so that no strategy of a benchmark starts from the truth."""
    from .soil import preset

    rng = np.random.default_rng(1000 + seed)
    base = preset(name).to_dict()
    for key in ("gamma", "cohesion", "adhesion", "phi", "delta", "k_c"):
        lo, hi = PAPER_BOUNDS[key]
        base[key] = float(np.clip(base[key] * math.exp(rng.normal(0.0, spread)), lo, hi * 0.999))
    return SoilParams(**base)


def random_bezier_path(rng: np.random.Generator, toe_x: float = 0.0, name: str = "random") -> BucketPath:
    """A random quadratic Bezier digging path for the default trapezoid pile (Fig. 8 style).

    Entry near the toe, a control point inside the pile, exit over the
    slope; random curl timing and final blade angle.
    """
    start = (toe_x + rng.uniform(-0.2, 0.05), rng.uniform(0.0, 0.08))
    control = (toe_x + rng.uniform(0.7, 1.3), rng.uniform(-0.02, 0.15))
    end = (toe_x + rng.uniform(1.2, 1.6), rng.uniform(0.9, 1.3))
    return bezier_path(start, control, end, curl_from=rng.uniform(0.45, 0.7),
                       angle_start=math.radians(rng.uniform(-10.0, 0.0)),
                       angle_end=math.radians(rng.uniform(35.0, 55.0)), name=name)
