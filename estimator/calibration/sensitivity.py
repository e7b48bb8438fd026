"""Global sensitivity of the predicted F_R along a path to each soil parameter: Sobol indices (SALib).

Which parameters can a cycle pin down? A parameter whose spread over its plausible range moves the
predicted resultant force along the path by a share of its variance that is negligible cannot be
calibrated from that path: whatever value the fit gives it comes from noise and from the other
parameters' misfit. The variance-based (Sobol) indices measure that share globally, over the whole
range, not at one point as the Jacobian does:

* first order ``S_i = V[E(Y | x_i)] / V[Y]``: the share of the variance ``x_i`` explains alone;
* total ``S_Ti = E[V(Y | x_~i)] / V[Y]``: its share with every interaction (``S_Ti`` near 0: ``x_i``
  can be fixed anywhere in its range without changing the prediction).

The output is the predicted F_R at each in-soil sample of the path (a vector). Its indices are
aggregated over the samples by variance weighting (Gamboa, Janon, Klein & Lagnoux 2014, the generalised
Sobol index of a multivariate output): ``S_i = sum_t V_t S_i(t) / sum_t V_t``. The indices of a set of
paths (several cycles) are those of their outputs joined, each path's F_R divided by its own variance
sum so that each path weighs the same.

Sampling and estimators are SALib's (Saltelli's extension of the Sobol sequence, ``sobol.sample``;
``sobol.analyze`` with bootstrap confidence intervals). SALib is an optional dependency (the ``model``
extra, ``pip install wheelloader[model]``); :func:`sobol_indices` raises :class:`ImportError` with the
install line when it is missing. The rest of the package does not need it.

The input distribution is uniform over :data:`SOBOL_RANGES` (the sinkage modulus ``K`` log-uniform: it
spans decades), a plausible box of the soils the continuum data cover, not the calibration's bounds,
whose cohesion up to 50 kPa would make every granular path a cohesion-only problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..checks import check_int
from ..errors import ParameterError
from ..force_model import DEFAULT_OPTIONS, ModelOptions
from ..kinematics import ContactState
from ..machine import Bucket
from ..soil_vector import SOIL_VECTOR_NAMES
from .fitmodel import FitData

__all__ = ["LOG_UNIFORM", "SOBOL_RANGES", "SobolResult", "identifiable", "sobol_indices"]

_DEG = math.pi / 180.0
#: Default input box of :func:`sobol_indices` per fit-vector parameter (SI; angles in rad): the soils of the
#: project's continuum data (gravel, sand, modified sand, dirt: gamma 1474 kg/m^3, cohesion and adhesion 0 to
#: 2.5 kPa, phi 39 to 44 deg, delta 22 to 38 deg, K 6e4 to 3e5 N/m^(n+2), n 1.2 to 1.5) with a margin, and the
#: granular class's density range (:mod:`~.priors`).
SOBOL_RANGES: dict[str, tuple[float, float]] = {
    "gamma": (1297.0, 2345.0), "cohesion": (0.0, 5000.0), "adhesion": (0.0, 5000.0),
    "phi": (30.0 * _DEG, 45.0 * _DEG), "delta": (15.0 * _DEG, 40.0 * _DEG), "K": (2.0e4, 1.0e6), "n": (0.9, 1.53)}
#: Parameters sampled log-uniformly over their range.
LOG_UNIFORM: frozenset[str] = frozenset({"K"})


@dataclass(frozen=True, eq=False)
class SobolResult:
    """Sobol indices of the predicted F_R along one path or a set of paths.

    Attributes
    ----------
    names : tuple of str
        The parameters (fit-vector names).
    first, total : dict
        Aggregated first-order and total index per name.
    first_conf, total_conf : dict
        Their 95 % bootstrap half-widths (variance-weighted like the indices).
    samples : int
        Model evaluations (``base * (len(names) + 2)``).
    points : int
        Output samples the indices aggregate (in-soil samples of the path(s), subsampled).
    local_total : numpy.ndarray
        ``points x names`` total index at each output sample (for plots), with ``local_depth`` [m].
    """

    names: tuple[str, ...]
    first: dict[str, float]
    total: dict[str, float]
    first_conf: dict[str, float]
    total_conf: dict[str, float]
    samples: int
    points: int
    local_total: np.ndarray = field(repr=False)
    local_depth: np.ndarray = field(repr=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping (without the local arrays)."""
        return {"names": list(self.names), "first": self.first, "total": self.total, "first_conf": self.first_conf,
                "total_conf": self.total_conf, "samples": self.samples, "points": self.points}


def _problem(ranges: dict[str, tuple[float, float]]) -> dict[str, Any]:
    names = tuple(ranges)
    for name in names:
        if name not in SOIL_VECTOR_NAMES:
            raise ParameterError(f"sobol: unknown parameter {name!r}; expected some of {list(SOIL_VECTOR_NAMES)}")
        lo, hi = ranges[name]
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo) or (name in LOG_UNIFORM and lo <= 0.0):
            raise ParameterError(f"sobol: range of {name} must be finite with high > low (> 0 if log-uniform), "
                                 f"got {(lo, hi)!r}")
    bounds = [[math.log(ranges[n][0]), math.log(ranges[n][1])] if n in LOG_UNIFORM else list(ranges[n])
              for n in names]
    return {"num_vars": len(names), "names": list(names), "bounds": bounds}


def _outputs(datas: list[FitData], rows: np.ndarray, names: tuple[str, ...], base: np.ndarray,
             points: list[np.ndarray]) -> list[np.ndarray]:
    """Predicted F_R at the chosen in-soil samples of each path, one row per input row."""
    idx = [SOIL_VECTOR_NAMES.index(n) for n in names]
    out = [np.empty((rows.shape[0], p.size)) for p in points]
    for r, row in enumerate(rows):
        x = base.copy()
        x[idx] = [math.exp(v) if n in LOG_UNIFORM else v for n, v in zip(names, row, strict=True)]
        for k, data in enumerate(datas):
            f_t, f_n, _ = data.forces(x)
            out[k][r] = np.hypot(f_t, f_n)[points[k]]
    return out


def sobol_indices(states: ContactState | list[ContactState], bucket: Bucket, options: ModelOptions = DEFAULT_OPTIONS,
                  ranges: dict[str, tuple[float, float]] | None = None, base: int = 256, points: int = 40,
                  seed: int = 0, nominal: np.ndarray | None = None, log_output: bool = True) -> SobolResult:
    """Aggregated Sobol indices of the predicted F_R along a path (or several) to the soil parameters.

    Parameters
    ----------
    states : ContactState or list of ContactState
        The path's contact state (depth, rho, alpha, fill ... as the calibration sees it:
        :meth:`~wheelloader.estimator.CycleLog.contact_state` or
        :func:`~wheelloader.estimator.force_models.cycle_contact_state`), or several paths' (the indices of the
        joined output: what several cycles determine together).
    bucket : Bucket
        The bucket (width, edge thickness).
    options : ModelOptions
        Force-model options.
    ranges : dict, optional
        ``{fit-vector name: (low, high)}`` of the parameters varied (default :data:`SOBOL_RANGES`); those not
        named stay at ``nominal``.
    base : int
        SALib's base sample count ``N`` (a power of 2); the model runs ``N (d + 2)`` times.
    points : int
        In-soil samples per path the indices aggregate (evenly spaced; all when fewer).
    seed : int
        Seed of the Sobol sequence's scrambling and of the bootstrap.
    nominal : numpy.ndarray, optional
        Fit vector of the parameters not varied (default: the middle of :data:`SOBOL_RANGES`).
    log_output : bool
        Indices of ``log F_R`` (default): of the relative change of the force, the measure the calibration's
        error is judged by; the variance of ``F_R`` itself is ruled by the few inputs that make it largest.

    Returns
    -------
    SobolResult

    Raises
    ------
    ImportError
        Without SALib (``pip install wheelloader[model]``).
    """
    try:
        from SALib.analyze import sobol as sobol_analyze
        from SALib.sample import sobol as sobol_sample
    except ImportError:
        raise ImportError("wheelloader: Sobol indices need SALib; install the optional extra: "
                          "pip install 'wheelloader[model]'") from None
    check_int("base", base)
    check_int("points", points)
    if base & (base - 1):
        raise ParameterError(f"base must be a power of 2 (Sobol sequence), got {base}")
    ranges = dict(SOBOL_RANGES if ranges is None else ranges)
    problem = _problem(ranges)
    names = tuple(problem["names"])
    states = [states] if isinstance(states, ContactState) else list(states)
    datas = [FitData.from_state(st, np.zeros(len(st)), np.zeros(len(st)), bucket, options, min_samples=1)
             for st in states]
    chosen = [np.unique(np.linspace(0, len(d) - 1, min(points, len(d))).round().astype(int)) for d in datas]
    mid = np.array([0.5 * (lo + hi) if n not in LOG_UNIFORM else math.sqrt(lo * hi)
                    for n, (lo, hi) in SOBOL_RANGES.items()])
    x0 = mid if nominal is None else np.asarray(nominal, float)
    rows = sobol_sample.sample(problem, base, calc_second_order=False, seed=seed)
    outs = _outputs(datas, rows, names, x0, chosen)
    if log_output:
        outs = [np.log(np.maximum(o, 1e-3)) for o in outs]
    # each path weighs the same: its outputs divided by the square root of its variance sum
    y = np.hstack([o / math.sqrt(max(float(np.sum(np.var(o, axis=0))), 1e-300)) for o in outs])
    depth = np.concatenate([d.depth[c] for d, c in zip(datas, chosen, strict=True)])
    var = np.var(y, axis=0)
    keep = var > 1e-12 * max(float(np.max(var)), 1e-300)
    s1, st, c1, ct = (np.zeros((int(keep.sum()), len(names))) for _ in range(4))
    for k, col in enumerate(np.flatnonzero(keep)):
        res = sobol_analyze.analyze(problem, y[:, col], calc_second_order=False, num_resamples=50, seed=seed)
        s1[k], st[k], c1[k], ct[k] = res["S1"], res["ST"], res["S1_conf"], res["ST_conf"]
    w = var[keep] / np.sum(var[keep])
    agg = lambda a: {n: float(v) for n, v in zip(names, w @ a, strict=True)}  # noqa: E731
    return SobolResult(names, agg(s1), agg(st), agg(c1), agg(ct), int(rows.shape[0]), int(keep.sum()),
                       st, depth[keep])


def identifiable(result: SobolResult, threshold: float = 0.05) -> tuple[str, ...]:
    """Names whose total index reaches ``threshold``: what the path(s) can pin down, in fit-vector order."""
    return tuple(n for n in SOIL_VECTOR_NAMES if n in result.total and result.total[n] >= threshold)
