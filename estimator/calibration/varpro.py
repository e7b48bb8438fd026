"""The ``"varpro"`` calibration (the default method): variable projection + global grid + analytic refinement.

For fixed nonlinear parameters ``(phi, delta, n)`` the forces are linear in
``theta_lin = (gamma, C, C_a, K)`` (see :mod:`wheelloader.estimator.calibration.fitmodel`),
so the eq-19 cost can be minimised exactly over ``theta_lin`` inside its
bounds (a 4-variable box-constrained least-squares problem,
:func:`wheelloader.estimator.calibration.boxqp.solve_box_qp`). What remains is a
3-parameter problem (the *projected* cost), which is searched globally on a
coarse grid:

1. beta* and the bearing factors are computed once per ``(phi, delta)`` grid
   pair, for all pairs at once (they do not depend on n or on the linear
   parameters);
2. the normal equations of every ``(phi, delta, n)`` grid point are built by
   a few matrix products and all box-constrained solves run in one batch;
3. the best few grid points that are local minima of the projected cost
   start a joint bounded nonlinear least-squares refinement of all seven
   identifiable parameters (``scipy.optimize.least_squares``, trust-region
   reflective) with the analytic Jacobian of
   :meth:`FitData.forces_and_jacobian`, which includes ``d beta*/d(phi, delta)``
   and the exact tension clamp;
4. a finer grid over one coarse ``(phi, delta)`` cell around the best
   solution looks for a deeper basin hidden between coarse grid points (the
   cost has kinks where beta* switches between its bounds) and refines it;
5. a previous cycle's result (warm start) is refined as one more start;
6. optionally (``regularize=True``; off by default, see below) the exact
   least-squares solution starts one more refinement, of the MAP estimate
   under a weak prior.

The grid makes the method independent of the initial guess; the refinement
makes the result exact to solver tolerance.

Weak prior (step 6)
-------------------
A cycle need not determine every parameter: on the DEM gravel path 1 the
cost is nearly flat along ``K w b d^n = const`` (eq 15), and the exact
minimiser is then one arbitrary point of a valley the data cannot resolve.
Step 6 resolves such directions with prior knowledge instead of solver
accident. It minimises

    eq 19a(x) + nu * sum_i ((x_i - m_i) / s_i)^2,

the negative log posterior (times ``2 nu``) of independent Gaussian priors
``x_i ~ N(m_i, s_i^2)`` (:func:`weak_prior`), with

* ``m``: the warm start ``initial`` when given, else the mid-range of the
  bounds (the paper's methods' initial guess,
  :func:`~wheelloader.estimator.calibration.paper_methods.mid_range_guess`, in the fit
  space);
* ``s_i = (hi_i - lo_i) / sqrt(12)``: the standard deviation of a uniform
  distribution over the bounds (eq 19j), i.e. the prior says no more than
  the bounds do, moment-matched; nothing is tuned per case;
* ``nu``: the noise variance per *independent* residual, estimated from the
  exact fit's residuals: ``nu = tau * sum r^2 / (M - p)``, with ``tau`` the
  integrated autocorrelation time of the residual series
  (:func:`~wheelloader.estimator.calibration.uncertainty.noise_per_effective_sample`);
  ``M / tau`` is the effective sample size, so correlated misfit is not
  mistaken for many independent measurements.

Locally, along a direction with data curvature ``h`` and prior curvature
``q`` (both per ``nu``), the estimate moves the fraction ``q / (h + q)`` of
its distance to ``m``: next to nothing where the data determine the
direction far better than the bounds do, all the way where the data leave it
flat -- there the estimate is the point nearest ``m`` (in units of ``s``)
among the parameters that fit equally well. A noise-free exact fit has
``nu`` at round-off level and is returned unchanged (an exactly
unidentifiable direction then stays where the search put it). The refinement is local, from the exact
solution.

Why it is off by default: on the DEM reference (the benchmark
``benchmarks/paper_experiments.py``) the honest noise level is high (model
misfit 37-60 % with residual autocorrelation times of 8-22 samples), so the
prior also pulls phi, delta and gamma, which the training cycle determines
no better than K and n: the training fit of every soil, 7 of the 12
unseen-gravel-path figures (paths 2-4, one deposition and seed-averaged,
filtered and unfiltered) and the dual cycle 2 get worse, and the comparison
with the multi-stage method holds on 4 of its 30 rows instead of 22. At no
weight of this prior (0.0001 to 30 times ``nu``) did the default beat the
multi-stage method on more than 8 of the 16 gravel path 1-4 rows, the exact
fit's count; nor at any confidence level of "the parameters nearest the
prior within the confidence region" (by the KKT conditions the same family
of solutions).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..errors import CalibrationError
from ..quantise import better
from .fitmodel import LINEAR_INDEX, FitData
from .result import SolverResult
from .uncertainty import noise_per_effective_sample
from .varpro_grid import projected_grid, starts_from_grid, weights

#: Default grid sizes over (phi, delta, n).
DEFAULT_GRID = (9, 9, 8)
#: Largest number of in-soil samples the grid search uses; longer cycles are searched on a uniform
#: subsample (every k-th sample), the refinement always runs on all of them. The grid only picks the
#: start points, so this bounds its time on long logs without changing where the refinement converges
#: for cycles of ordinary length.
GRID_MAX_SAMPLES = 20_000
#: Largest number of in-soil samples the grid search uses when several cycles are fitted together (every k-th
#: sample of all of them; about two cycles' worth): it keeps a five-cycle calibration's grid at the cost of a
#: two-cycle one. The refinement always runs on every sample.
GRID_MAX_SAMPLES_CYCLES = 600
#: A later grid start whose iterate comes within this distance of an earlier start's solution (in every free
#: parameter, relative to that solution's magnitude, at least 1e-3 of the bound range) has joined its basin
#: and is stopped there; it would end in (nearly) the same solution, which the near-tie rule gives to the
#: earlier start (:func:`first_best`). Measured on 85 cycles (the calibration benchmark's training and
#: robustness cycles, every ``data/mpm`` cycle, 12 ``data/reference`` ones) against no stopping: 15 % fewer
#: refinement evaluations; every cost within 1e-9 and every parameter within 1e-6 but one cycle's, moved by
#: 0.2 % along a flat valley at a cost 1e-11 higher.
BASIN_RADIUS = 0.3
#: Model evaluations a later start makes before the basin test applies (an iteration count, not a time).
BASIN_CHECK_FROM = 3

_log = logging.getLogger(__name__)


@dataclass
class Evaluations:
    """Counters of model work: parameter sets at which forces were evaluated, and Jacobians."""

    nfev: int = 0
    njev: int = 0


@dataclass(frozen=True)
class Prior:
    """Independent Gaussian prior ``x_i ~ N(mean_i, scale_i^2)`` on the fit vector, with noise ``nu``.

    :func:`refine` with a prior minimises ``eq 19a + nu * sum ((x_i - mean_i) /
    scale_i)^2`` (the negative log posterior times ``2 nu``); parameters with
    ``scale_i = 0`` have no prior term.
    """

    mean: np.ndarray
    scale: np.ndarray
    nu: float

    def weights(self) -> np.ndarray:
        """``sqrt(nu) / scale_i`` (0 where ``scale_i`` is 0): rows of the prior residual."""
        scale = np.asarray(self.scale, float)
        return np.where(scale > 0, math.sqrt(self.nu) / np.where(scale > 0, scale, 1.0), 0.0)


def weak_prior(lo: np.ndarray, hi: np.ndarray, nu: float, mean: np.ndarray | None = None) -> Prior:
    """The weak prior of the default method (module docstring): uniform-over-the-bounds moments.

    Scale ``(hi - lo) / sqrt(12)`` (standard deviation of a uniform
    distribution over the bounds); mean ``mean`` (a warm start) if given, else
    the mid-range ``(lo + hi) / 2`` (the paper's methods' initial guess).
    """
    centre = 0.5 * (lo + hi) if mean is None else np.clip(np.asarray(mean, float), lo, hi)
    return Prior(centre, (hi - lo) / math.sqrt(12.0), float(nu))


def refine(data: FitData, x0: np.ndarray, lo: np.ndarray, hi: np.ndarray, lam: float = 0.5,
           counter: Evaluations | None = None, max_nfev: int = 100, xtol: float = 1e-8,
           ftol: float = 1e-10, gtol: float = 1e-10, prior: Prior | None = None,
           basins: list[np.ndarray] | None = None) -> SolverResult:
    """Joint bounded least squares on the seven fit parameters with the analytic Jacobian.

    Parameters whose bounds coincide are held fixed. With a ``prior`` the
    residual gets one row ``sqrt(nu) (x_i - mean_i) / scale_i`` per free
    parameter (see :class:`Prior`). With ``basins`` (earlier starts' solutions) the refinement stops
    once an iterate, from the :data:`BASIN_CHECK_FROM`-th evaluation on, lies within
    :data:`BASIN_RADIUS` of one of them.

    Returns
    -------
    SolverResult
        ``cost`` is eq 19a (sum of weighted squared residuals, data only) at ``x``; also ``start`` (the
        start point) and ``objective`` (``cost`` plus the prior term, equal to ``cost`` without a prior);
        a refinement stopped in a basin has ``success`` False and ``joined``, the index in ``basins``.
    """
    wt, wn = weights(lam)
    free = hi > lo
    x_fixed = np.clip(np.asarray(x0, float), lo, hi)
    counter = counter if counter is not None else Evaluations()
    cache: dict[str, object] = {}
    m = len(data)
    if prior is not None:
        pw = prior.weights()[free]
        pmean = np.asarray(prior.mean, float)[free]
        prior_jac = np.diag(pw)

    def full(z):
        x = x_fixed.copy()
        x[free] = z
        return x

    span_all = hi - lo
    evaluations = [0]

    def evaluate(z):
        key = z.tobytes()
        if cache.get("key") != key:
            f_t, f_n, jt, jn = data.forces_and_jacobian(full(z))
            counter.nfev += 1
            counter.njev += 1
            evaluations[0] += 1
            cache["key"] = key
            r = [wt * (f_t - data.y_t), wn * (f_n - data.y_n)]
            jac = [wt * jt[:, free], wn * jn[:, free]]
            if data.weight is not None:
                rw = data.root_weight
                r = [v * rw for v in r]
                jac = [v * rw[:, None] for v in jac]
            if prior is not None:
                r.append(pw * (z - pmean))
                jac.append(prior_jac)
            cache["r"] = np.concatenate(r)
            cache["J"] = np.vstack(jac)
            if basins and evaluations[0] >= BASIN_CHECK_FROM:
                x = full(z)
                for j, b in enumerate(basins):
                    scale_b = np.maximum(np.abs(b), 1e-3 * span_all)[free]
                    if np.all(np.abs(x - b)[free] < BASIN_RADIUS * scale_b):
                        raise _JoinedBasin(j, x, float(cache["r"] @ cache["r"]), evaluations[0])
        return cache

    def fun(z):
        return evaluate(z)["r"]

    def jac(z):
        return evaluate(z)["J"]

    z0 = x_fixed[free]
    # trf needs a strictly interior start: nudge bound values inside by a hair
    span = hi[free] - lo[free]
    z0 = np.clip(z0, lo[free] + 1e-10 * span, hi[free] - 1e-10 * span)
    scale = np.where(span > 0, span, 1.0)
    # scale: typical magnitude of each parameter (K's bound range is far larger than its typical values)
    typical = np.maximum(np.abs(z0), 1e-3 * scale)
    try:
        res = least_squares(fun, z0, jac=jac, bounds=(lo[free], hi[free]), method="trf", x_scale=typical,
                            xtol=xtol, ftol=ftol, gtol=gtol, max_nfev=max_nfev)
    except _JoinedBasin as stop:
        return SolverResult(stop.x, stop.cost, False, 0, f"stopped after {stop.evaluations} evaluations: joined the "
                            f"basin of an earlier start", stop.evaluations, stop.evaluations,
                            start=np.asarray(x0, float), objective=stop.cost, joined=stop.index)
    x = full(res.x)
    objective = float(2.0 * res.cost)
    cost = objective if prior is None else float(np.sum(res.fun[:2 * m] ** 2))
    return SolverResult(x, cost, bool(res.success), int(res.status), str(res.message), int(res.nfev),
                        int(res.njev), start=np.asarray(x0, float), objective=objective)


class _JoinedBasin(Exception):
    """Raised inside :func:`refine` when an iterate enters an earlier start's basin."""

    def __init__(self, index: int, x: np.ndarray, cost: float, evaluations: int) -> None:
        super().__init__(index)
        self.index, self.x, self.cost, self.evaluations = index, x, cost, evaluations


def polish_linear(data: FitData, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, lam: float,
                  counter: Evaluations) -> tuple[np.ndarray, float] | None:
    """Re-solve ``(gamma, C, C_a, K)`` exactly at the nonlinear parameters of ``x``; ``(x_new, eq-19 cost)``.

    The bounded nonlinear solver approaches parameters that sit on a bound
    (C = 0 for a cohesionless soil, say) only asymptotically; the exact box
    solve lands on the bound. The cost is re-evaluated with the full model
    (tension clamp included); ``None`` if the tension clamp is active.
    """
    _, theta = projected_grid(data, lo, hi, np.array([x[3]]), np.array([x[4]]), np.array([x[6]]), lam)
    x_new = x.copy()
    x_new[list(LINEAR_INDEX)] = theta[0, 0, 0]
    f_t, f_n, tension = data.forces(x_new)
    counter.nfev += 1
    if np.any(tension):
        return None
    if data.weight is not None:
        return x_new, float(lam * np.sum(data.weight * (f_t - data.y_t) ** 2)
                            + (1.0 - lam) * np.sum(data.weight * (f_n - data.y_n) ** 2))
    return x_new, float(lam * np.sum((f_t - data.y_t) ** 2) + (1.0 - lam) * np.sum((f_n - data.y_n) ** 2))


def first_best(results: list[SolverResult], key: str = "cost") -> SolverResult:
    """The best of ``results`` by ``key``, where a later one wins only by more than the near-tie tolerance.

    On a near-tie (:func:`~wheelloader.estimator.quantise.better`) the earlier result in the fixed order of
    the starts stays, so last-bit differences between CPUs do not pick another basin.
    """
    best = results[0]
    for r in results[1:]:
        if better(getattr(r, key), getattr(best, key)):
            best = r
    return best


def fit_varpro(data: FitData, lo: np.ndarray, hi: np.ndarray, lam: float = 0.5, initial: np.ndarray | None = None,
               grid: tuple[int, int, int] = DEFAULT_GRID, n_starts: int = 3, max_nfev: int = 100,
               zoom: int = 7, regularize: bool = False,
               prior_moments: tuple[np.ndarray, np.ndarray] | None = None) -> SolverResult:
    """Variable-projection grid search, analytic refinement, then a zoomed grid (module docstring).

    The zoom step re-grids ``(phi, delta)`` with ``zoom x zoom`` points over
    one coarse cell around the best refined solution (the landscape has kinks
    where beta* switches between its bounds, which can hide a deeper basin
    inside a coarse cell) and refines the zoomed grid's best local minima
    whose projected cost undercuts the best solution so far. With
    ``regularize`` the exact least-squares solution then starts the MAP
    refinement under :func:`weak_prior` (module docstring, step 6).

    Returns
    -------
    SolverResult
        The best refinement's ``x``, ``cost`` (eq 19a), ``success``, ``status``, ``message``; ``nfev`` and
        ``njev`` count all model work (every grid point). Also ``evaluations`` (:class:`Evaluations`),
        ``grid_time``, ``refine_time`` [s], ``grid_best``, ``grid_cost`` (best grid point and its projected
        cost), ``refinements`` (every refinement's :class:`SolverResult`), ``exact``, ``exact_cost`` (the
        least-squares solution before the prior), ``prior`` (:class:`Prior` or None) and ``tau``.

    Raises
    ------
    CalibrationError
        If the projected cost is not finite anywhere on the grid.
    """
    counter = Evaluations()
    t0 = time.perf_counter()
    nl = (3, 4, 6)
    axes = [np.linspace(lo[i], hi[i], m) if hi[i] > lo[i] else np.array([lo[i]]) for i, m in zip(nl, grid, strict=True)]
    stride = -(-len(data) // GRID_MAX_SAMPLES)
    if data.cycle is not None:  # several cycles: the grid only picks start points, a subsample of them does
        stride = max(stride, -(-len(data) // GRID_MAX_SAMPLES_CYCLES))
    grid_data = data.every(stride)
    if stride > 1:
        _log.info("varpro: grid search on every %d-th of %d in-soil samples (GRID_MAX_SAMPLES %d)", stride,
                  len(data), GRID_MAX_SAMPLES)
    cost, theta = projected_grid(grid_data, lo, hi, axes[0], axes[1], axes[2], lam)
    counter.nfev += cost.size
    starts = [x for _, x in starts_from_grid(cost, theta, axes, n_starts)]
    if not starts:
        raise CalibrationError("projected cost is not finite anywhere on the grid: the forces or the geometry "
                               "cannot be fit by any soil on the grid")
    grid_best, grid_cost = starts[0].copy(), float(np.min(cost))
    if initial is not None:
        starts.insert(0, np.clip(np.asarray(initial, float), lo, hi))
    t1 = time.perf_counter()
    _log.info("varpro: %d grid points in %.2f s; refining %d start(s) on %d samples", cost.size, t1 - t0,
              len(starts), len(data))
    results: list[SolverResult] = []
    for x0 in starts:  # a later start that joins an earlier one's basin stops there (BASIN_RADIUS)
        basins = [r.x for r in results if "joined" not in r]
        results.append(refine(data, x0, lo, hi, lam, counter, max_nfev=max_nfev, basins=basins))
    best = first_best([r for r in results if "joined" not in r])
    if zoom > 1:
        best = _zoom(data, grid_data, best, axes, lo, hi, lam, zoom, counter, max_nfev, results)
    polished = polish_linear(data, best.x, lo, hi, lam, counter)
    if polished is not None and better(polished[1], best.cost):
        best = SolverResult(polished[0], polished[1], best.success, best.status,
                            best.message + " (linear parameters polished by the exact bounded solve)",
                            best.nfev, best.njev, start=best.start, objective=polished[1])
    exact, exact_cost, prior, tau = best.x, best.cost, None, float("nan")
    if regularize:
        best, prior, tau = _map_estimate(data, best, lo, hi, lam, initial, prior_moments, counter, max_nfev, results)
    t2 = time.perf_counter()
    return SolverResult(best.x, best.cost, best.success, best.status, best.message, counter.nfev, counter.njev,
                        time_s=t2 - t0, evaluations=counter, grid_time=t1 - t0, refine_time=t2 - t1,
                        grid_best=grid_best, grid_cost=grid_cost, refinements=results, exact=exact,
                        exact_cost=exact_cost, prior=prior, tau=tau)


def _zoom(data: FitData, grid_data: FitData, best: SolverResult, axes: list[np.ndarray], lo: np.ndarray,
          hi: np.ndarray, lam: float, zoom: int, counter: Evaluations, max_nfev: int,
          results: list[SolverResult]) -> SolverResult:
    """Step 4: a ``zoom x zoom`` grid over the coarse ``(phi, delta)`` cell around ``best``; its best local
    minima that undercut ``best`` are refined (appended to ``results``). Returns the new best."""
    zaxes = []
    for k, i in enumerate((3, 4)):
        step = (hi[i] - lo[i]) / max(len(axes[k]) - 1, 1)
        a, b = max(lo[i], best.x[i] - step), min(hi[i], best.x[i] + step)
        zaxes.append(np.linspace(a, b, zoom) if b > a else np.array([a]))
    zaxes.append(axes[2])
    zcost, ztheta = projected_grid(grid_data, lo, hi, zaxes[0], zaxes[1], zaxes[2], lam)
    counter.nfev += zcost.size
    for c, x0 in starts_from_grid(zcost, ztheta, zaxes, 2):
        if better(c, best.cost):
            r = refine(data, x0, lo, hi, lam, counter, max_nfev=max_nfev)
            results.append(r)
            if better(r.cost, best.cost):
                best = r
    return best


def _map_estimate(data: FitData, best: SolverResult, lo: np.ndarray, hi: np.ndarray, lam: float,
                  initial: np.ndarray | None, prior_moments: tuple[np.ndarray, np.ndarray] | None,
                  counter: Evaluations, max_nfev: int,
                  results: list[SolverResult]) -> tuple[SolverResult, Prior | None, float]:
    """Step 6: the MAP estimate from the exact fit ``best`` (module docstring); ``(best, prior, tau)``."""
    f_t, f_n, _ = data.forces(best.x)
    counter.nfev += 1
    wt, wn = weights(lam)
    rw = data.root_weight
    nu, tau = noise_per_effective_sample([rw * wt * (f_t - data.y_t), rw * wn * (f_n - data.y_n)],
                                         int(np.sum(hi > lo)))
    if not nu > 0.0:
        return best, None, tau
    if prior_moments is None:
        prior = weak_prior(lo, hi, nu, initial)
        r = refine(data, best.x, lo, hi, lam, counter, max_nfev=max_nfev, prior=prior)
    else:  # a literature prior (priors.py): also start from its mean, the exact fit may sit in another basin
        mean, scale = (np.asarray(v, float) for v in prior_moments)
        prior = Prior(np.where(scale > 0, np.clip(mean, lo, hi), best.x), scale, float(nu))
        from_mean = best.x.copy()
        from_mean[scale > 0] = np.clip(mean, lo, hi)[scale > 0]
        runs = [refine(data, x0, lo, hi, lam, counter, max_nfev=max_nfev, prior=prior) for x0 in (best.x, from_mean)]
        r = first_best(runs, "objective")
    results.append(r)
    return (SolverResult(r.x, r.cost, r.success, r.status,
                         f"{r.message} (MAP under the weak prior, nu {nu:.4g} N^2, tau {tau:.3g})",
                         r.nfev, r.njev, start=r.start, objective=r.objective), prior, tau)
