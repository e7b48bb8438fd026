"""The paper's calibration methods (Section III), kept as faithful baselines.

Both use ``scipy.optimize.minimize(method="L-BFGS-B")`` on the raw (unscaled)
parameters with finite-difference gradients (scipy's default forward
differences, absolute step 1e-8), ``options={"maxiter": 1000, "gtol": 1e-5}``
and the paper's bounds (eq 19j). The force model is the same vectorised
model as the default method's (:class:`~wheelloader.estimator.calibration.fitmodel.FitData`,
identical to :func:`~wheelloader.estimator.force_model.soil_forces`) and
runs on the same in-soil samples, so speed comparisons are like for like.

* ``single-stage`` (Section III-A): all eight parameters at once, eq 19 with
  lambda = 0.5.
* ``multi-stage`` (Section III-B): stage 1 fits ``theta_1 = [C_a, delta, k_c,
  k_phi, n]`` to F_T with F rebuilt from the observed F_N (eqs 20-23);
  stage 2 fits ``theta_2 = [gamma, C, phi]`` to the reconstructed FEE force
  ``F_obs = F_N,obs / cos(delta*)`` (eq 25), Gaussian-filtered in time, with
  ``C_a*`` and ``delta*`` fixed (eq 27); stage 3 refits ``theta_3 = [k_c,
  k_phi, n]`` with eq 19 and lambda = 1 (eq 28), all else fixed.

Initial guess ("the paper's kind"): the paper initialises "from values
within the soil parameter ranges"; we use the mid-point of each bound
(:func:`mid_range_guess`) unless the caller gives one. Each stage of the
multi-stage method starts its parameters from that guess, except stage 3,
which starts from stage 1's ``k_c, k_phi, n``.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.optimize import minimize

from ..soil import PARAMETER_NAMES, SoilParams
from ..soil_vector import soil_vector
from .fitmodel import FitData
from .result import SolverResult

#: L-BFGS-B options of the paper's methods.
PAPER_OPTIONS = {"maxiter": 1000, "gtol": 1e-5}
#: Default standard deviation of the stage-2 Gaussian filter [samples].
DEFAULT_SIGMA = 3.0


def mid_range_guess(bounds: dict[str, tuple[float, float]]) -> np.ndarray:
    """Mid-point of every bound, in :data:`PARAMETER_NAMES` order."""
    return np.array([0.5 * (bounds[k][0] + bounds[k][1]) for k in PARAMETER_NAMES])


#: Result of one L-BFGS-B run (a stage): :class:`SolverResult` with ``name`` (stage), ``names`` (its
#: parameters), ``extra`` (per-stage data: predictions, filtered signal) besides the common keys.
PaperStage = SolverResult


def paper_fit(theta: np.ndarray, stages: list[SolverResult], initial: np.ndarray) -> SolverResult:
    """Result of a paper method: :class:`SolverResult` with ``theta`` (the eight parameters, eq 18), ``stages``
    and ``initial``; ``cost``, ``success``, ``nfev``, ``nit``, ``time_s`` summarise the stages (status and
    message of the first stage that failed, else of the last)."""
    failed = [s for s in stages if not s.success]
    last = failed[0] if failed else stages[-1]
    return SolverResult(theta, stages[-1].cost, not failed, last.status, last.message,
                        sum(s.nfev for s in stages), 0, sum(s.nit for s in stages), sum(s.time_s for s in stages),
                        theta=np.asarray(theta, dtype=float), stages=stages, initial=np.asarray(initial, dtype=float))


def _run_lbfgsb(name: str, names: tuple[str, ...], fun, x0: np.ndarray, bounds, maxiter: int = 1000,
                **extra) -> SolverResult:
    calls = [0]

    def counted(x):
        calls[0] += 1
        return fun(x)

    t0 = time.perf_counter()
    res = minimize(counted, x0, method="L-BFGS-B", bounds=bounds, options={**PAPER_OPTIONS, "maxiter": int(maxiter)})
    dt = time.perf_counter() - t0
    msg = res.message if isinstance(res.message, str) else res.message.decode()
    return SolverResult(res.x, float(res.fun), bool(res.success), int(res.status), msg, calls[0], 0, int(res.nit), dt,
                        name=name, names=names, extra=dict(extra))


def _clip_guess(x0: np.ndarray, bounds: dict[str, tuple[float, float]]) -> np.ndarray:
    lo = np.array([bounds[k][0] for k in PARAMETER_NAMES])
    hi = np.array([bounds[k][1] for k in PARAMETER_NAMES])
    return np.clip(np.asarray(x0, float), lo, hi)


def fit_single_stage(data: FitData, bounds: dict[str, tuple[float, float]],
                     initial: SoilParams | None = None, maxiter: int = 1000) -> SolverResult:
    """Section III-A: eq 19 with lambda = 0.5 over all eight parameters."""
    b = data.edge_thickness
    x0 = _clip_guess(initial.to_array() if initial is not None else mid_range_guess(bounds), bounds)

    def cost(theta):
        f_t, f_n, _ = data.forces(soil_vector(theta, b))
        return 0.5 * float(np.sum((data.y_t - f_t) ** 2)) + 0.5 * float(np.sum((data.y_n - f_n) ** 2))  # eq 19a

    stage = _run_lbfgsb("single-stage", PARAMETER_NAMES, cost, x0, [bounds[k] for k in PARAMETER_NAMES],
                        maxiter)
    return paper_fit(stage.x, [stage], x0)


def fit_multi_stage(data: FitData, bounds: dict[str, tuple[float, float]], initial: SoilParams | None = None,
                    sigma: float = DEFAULT_SIGMA, observed_normal_full: np.ndarray | None = None,
                    maxiter: int = 1000) -> SolverResult:
    """Section III-B: stages 1-3 (eqs 20-28).

    Parameters
    ----------
    data : FitData
        In-soil samples of the cycle.
    bounds : dict
        Bounds of the eight parameters.
    initial : SoilParams, optional
        Initial guess (default: mid-range of ``bounds``).
    sigma : float
        Standard deviation of the stage-2 Gaussian filter on ``F_obs`` [samples];
        0 disables the filter.
    observed_normal_full : numpy.ndarray, optional
        The whole cycle's measured F_N (all samples, in time order), so the
        filter runs over the continuous signal; default: the in-soil samples.
    maxiter : int
        L-BFGS-B iteration limit per stage (paper: 1000).
    """
    b, w = data.edge_thickness, data.width
    x0 = _clip_guess(initial.to_array() if initial is not None else mid_range_guess(bounds), bounds)
    theta = x0.copy()
    i = {name: k for k, name in enumerate(PARAMETER_NAMES)}
    sink_wb = w * b
    wl = w * data.blade_length
    logd = np.log(data.depth)

    # Stage 1 (eqs 21-23): theta_1 = [C_a, delta, k_c, k_phi, n]
    names1 = ("adhesion", "delta", "k_c", "k_phi", "n")

    def model1(t1):
        ca, delta, kc, kp, n = t1
        return sink_wb * (kc / b + kp) * np.exp(n * logd) + data.y_n * math.tan(delta) + ca * wl  # eq 21

    def cost1(t1):
        return float(np.sum((data.y_t - model1(t1)) ** 2))  # eq 23a

    s1 = _run_lbfgsb("stage 1", names1, cost1, theta[[i[k] for k in names1]], [bounds[k] for k in names1], maxiter)
    for k, v in zip(names1, s1.x, strict=True):
        theta[i[k]] = v
    s1.extra["prediction"] = model1(s1.x)

    # Stage 2 (eqs 25-27): theta_2 = [gamma, C, phi], F_obs = F_N,obs / cos(delta*), Gaussian-filtered
    delta_s = theta[i["delta"]]
    from scipy.ndimage import gaussian_filter1d  # here, not at the top: scipy.ndimage takes ~1 s to import

    if observed_normal_full is not None:
        f_obs_full = np.asarray(observed_normal_full, float) / math.cos(delta_s)  # eq 25
        f_filt_full = gaussian_filter1d(f_obs_full, sigma, mode="nearest") if sigma > 0 else f_obs_full
        f_obs, f_filt = f_obs_full[data.index], f_filt_full[data.index]
    else:
        f_obs = data.y_n / math.cos(delta_s)
        f_filt = gaussian_filter1d(f_obs, sigma, mode="nearest") if sigma > 0 else f_obs
    names2 = ("gamma", "cohesion", "phi")

    def fee2(t2):
        th = theta.copy()
        th[[i[k] for k in names2]] = t2
        f_t, f_n, _ = data.forces(soil_vector(th, b))
        return f_n / math.cos(delta_s)  # F of eq 27b (F_N = F cos delta)

    def cost2(t2):
        return float(np.sum((f_filt - fee2(t2)) ** 2))  # eq 27a

    s2 = _run_lbfgsb("stage 2", names2, cost2, theta[[i[k] for k in names2]], [bounds[k] for k in names2],
                     maxiter, sigma=float(sigma))
    for k, v in zip(names2, s2.x, strict=True):
        theta[i[k]] = v
    s2.extra.update(prediction=fee2(s2.x), observed=f_obs, filtered=f_filt)

    # Stage 3 (eq 28): theta_3 = [k_c, k_phi, n], eq 19 with lambda = 1
    names3 = ("k_c", "k_phi", "n")

    def ft3(t3):
        th = theta.copy()
        th[[i[k] for k in names3]] = t3
        return data.forces(soil_vector(th, b))[0]

    def cost3(t3):
        return float(np.sum((data.y_t - ft3(t3)) ** 2))  # eq 19a, lambda = 1

    s3 = _run_lbfgsb("stage 3", names3, cost3, theta[[i[k] for k in names3]], [bounds[k] for k in names3], maxiter)
    for k, v in zip(names3, s3.x, strict=True):
        theta[i[k]] = v
    s3.extra["prediction"] = ft3(s3.x)
    return paper_fit(theta, [s1, s2, s3], x0)
