"""Covariance, standard errors and an identifiability report from the fit Jacobian.

Works on the seven identifiable fit parameters :data:`~wheelloader.estimator.calibration.fitmodel.FIT_NAMES`
(``K = k_c / b + k_phi`` instead of k_c, k_phi, which forces cannot separate).

* Covariance: ``s^2 (J^T J)^-1`` over the parameters not held by a bound,
  with ``J`` the Jacobian of the weighted eq-19 residual and ``s^2`` the
  residual variance ``sum r^2 / (m - p)``. Parameters on a bound get NaN.
* Identifiability: the same Fisher information judged at an effective noise
  level ``sigma_eff = max(s, 1 % of the mean observed |F_R|)`` so that
  noise-free data do not make every parameter look determined. A
  parameter's relative standard error (standard error / typical magnitude,
  typical magnitude = max(|value|, 1e-3 x bound range)) below 10 % means
  *determined*, below 100 % *weakly determined*, else *not determined*.
  Combinations: the singular directions of the magnitude-scaled Jacobian
  whose relative standard error exceeds 10 % are listed with their dominant
  components (the combinations this cycle did not pin down).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..soil import format_value
from .fitmodel import FIT_NAMES

#: Relative standard error limits for "determined" and "weakly determined".
DETERMINED_RSE = 0.10
WEAK_RSE = 1.0
#: Reference noise level, as a fraction of the mean observed |F_R|.
REFERENCE_NOISE = 0.01

KC_KPHI_NOTE = ("k_c and k_phi enter the forces only as K = k_c/b + k_phi (eq 15): K is estimated, the split "
                "into k_c and k_phi is a convention (prior's share of k_c/b in K if a prior/initial guess is "
                "given, else all of K in k_phi, moved inside the bounds), not an estimate.")


@dataclass
class Uncertainty:
    """Covariance and identifiability of one calibration (see module docstring).

    Attributes
    ----------
    names : tuple of str
        :data:`FIT_NAMES`.
    values : numpy.ndarray
        Fit vector at the solution.
    covariance : numpy.ndarray
        7 x 7 covariance (NaN rows/columns for parameters on a bound).
    std_errors : numpy.ndarray
        Standard errors (NaN on a bound).
    residual_std : float
        ``s``: weighted residual standard deviation [N].
    effective_noise : float
        ``sigma_eff`` used for the identifiability judgement [N].
    status : dict
        name -> "determined" | "weakly determined" | "not determined" | "at bound".
    relative_std_errors : numpy.ndarray
        Relative standard errors at ``sigma_eff``.
    weak_combinations : list of dict
        ``{"relative_std": float, "combination": {name: coefficient}}``.
    condition_number : float
        Of the magnitude-scaled Jacobian of the free parameters.
    """

    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray = field(repr=False)
    std_errors: np.ndarray
    residual_std: float
    effective_noise: float
    status: dict[str, str]
    relative_std_errors: np.ndarray
    weak_combinations: list[dict[str, Any]]
    condition_number: float

    @property
    def determined(self) -> list[str]:
        """Parameters this cycle determined (plus K's meaning: k_c, k_phi only through K)."""
        return [n for n in self.names if self.status[n] == "determined"]

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable report."""
        def num(v: float) -> float | None:
            return None if not np.isfinite(v) else float(v)

        return {
            "parameters": {
                n: {"value": float(self.values[i]), "std_error": num(self.std_errors[i]),
                    "relative_std_error_at_effective_noise": num(self.relative_std_errors[i]),
                    "status": self.status[n]}
                for i, n in enumerate(self.names)
            },
            "determined": self.determined,
            "weakly_determined": [n for n in self.names if self.status[n] == "weakly determined"],
            "not_determined": [n for n in self.names if self.status[n] == "not determined"],
            "at_bound": [n for n in self.names if self.status[n] == "at bound"],
            "weak_combinations": self.weak_combinations,
            "k_c_k_phi": KC_KPHI_NOTE,
            "residual_std_N": float(self.residual_std),
            "effective_noise_N": float(self.effective_noise),
            "condition_number": num(self.condition_number),
            "covariance": [[num(v) for v in row] for row in self.covariance],
        }

    def describe(self) -> str:
        """Human-readable lines."""
        lines = []
        for i, n in enumerate(self.names):
            se = self.std_errors[i]
            se_txt = "   n/a    " if not np.isfinite(se) else f"{se:10.4g}"
            lines.append(f"  {n:>9} = {format_value(self.values[i]):>12}  +- {se_txt}  {self.status[n]}")
        for c in self.weak_combinations:
            terms = " ".join(f"{v:+.2f}*{k}" for k, v in c["combination"].items())
            rel = c["relative_std"]
            # None: a direction the data do not see at all (zero singular value, infinite standard error)
            rel_txt = "infinite: not seen by the data" if rel is None else f"{rel:.2g}"
            lines.append(f"  weak combination (rel. std {rel_txt}): {terms}")
        lines.append("  " + KC_KPHI_NOTE)
        return "\n".join(lines)


def analyse(jacobian: np.ndarray, residual: np.ndarray, x: np.ndarray, lo: np.ndarray, hi: np.ndarray,
            force_scale: float) -> Uncertainty:
    """Build :class:`Uncertainty` from the weighted residual Jacobian at the solution.

    Parameters
    ----------
    jacobian : numpy.ndarray
        ``(m, 7)`` Jacobian of the weighted residual w.r.t. :data:`FIT_NAMES`.
    residual : numpy.ndarray
        ``(m,)`` weighted residual.
    x, lo, hi : numpy.ndarray
        Solution and bounds of the fit vector.
    force_scale : float
        Mean observed |F_R| [N] (for the reference noise level).
    """
    p = len(FIT_NAMES)
    m = residual.size
    span = hi - lo
    tol = 1e-7 * np.where(span > 0, span, 1.0)
    at_bound = (x <= lo + tol) | (x >= hi - tol)
    free = ~at_bound
    typical = np.maximum(np.abs(x), 1e-3 * np.where(span > 0, span, 1.0))
    dof = max(m - int(free.sum()), 1)
    s = float(np.sqrt(np.sum(residual**2) / dof))
    sigma_eff = max(s, REFERENCE_NOISE * force_scale)
    cov = np.full((p, p), np.nan)
    rse = np.full(p, np.nan)
    combos: list[dict[str, Any]] = []
    cond = float("nan")
    fi = np.flatnonzero(free)
    if fi.size:
        js = jacobian[:, fi] * typical[fi]
        u, sv, vt = np.linalg.svd(js, full_matrices=False)
        cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        cutoff = sv[0] * 1e-14
        inv_sv = np.where(sv > cutoff, 1.0 / np.where(sv > cutoff, sv, 1.0), np.inf)
        # (Js^T Js)^-1 = V diag(1/sv^2) V^T; infinite where the direction is not seen at all
        with np.errstate(invalid="ignore"):
            scaled_cov = (vt.T * inv_sv**2) @ vt if np.all(np.isfinite(inv_sv)) else None
        if scaled_cov is not None:
            cov_f = s**2 * scaled_cov * np.outer(typical[fi], typical[fi])
            cov[np.ix_(fi, fi)] = cov_f
            rse[fi] = sigma_eff * np.sqrt(np.diag(scaled_cov))
        else:
            rse[fi] = np.inf
        for k in range(sv.size):
            rel = sigma_eff * inv_sv[k]
            if rel > DETERMINED_RSE:
                vec = vt[k]
                order = np.argsort(-np.abs(vec))
                comp = {FIT_NAMES[fi[j]]: round(float(vec[j]), 3) for j in order if abs(vec[j]) > 0.2}
                combos.append({"relative_std": float(rel) if np.isfinite(rel) else None, "combination": comp})
    std = np.sqrt(np.diag(cov))
    status = {}
    for i, n in enumerate(FIT_NAMES):
        if at_bound[i]:
            status[n] = "at bound"
        elif rse[i] < DETERMINED_RSE:
            status[n] = "determined"
        elif rse[i] < WEAK_RSE:
            status[n] = "weakly determined"
        else:
            status[n] = "not determined"
    return Uncertainty(FIT_NAMES, np.asarray(x, float).copy(), cov, std, s, sigma_eff, status, rse, combos, cond)


# ------------------------------------------------------------ noise of autocorrelated residuals
#: Window constant of :func:`integrated_autocorrelation_time` (Sokal's choice).
SOKAL_WINDOW = 5.0


def integrated_autocorrelation_time(series: np.ndarray, window: float = SOKAL_WINDOW) -> float:
    """Integrated autocorrelation time ``tau = 1 + 2 sum_{k>=1} rho_k`` of a series (>= 1).

    The autocorrelation ``rho_k`` is the sample autocorrelation (FFT, mean
    removed); the sum is cut at the smallest lag ``M`` with ``M >= window *
    tau(M)`` (Sokal's adaptive window, as used for MCMC chains). ``N / tau``
    is the effective number of independent samples in a series of ``N``:
    the variance of a mean, or of a least-squares estimate whose regressors
    vary more slowly than the noise, is ``tau`` times the white-noise value.
    A constant or zero series returns 1.
    """
    r = np.asarray(series, float).ravel()
    n = r.size
    if n < 2:
        return 1.0
    r = r - r.mean()
    spec = np.fft.rfft(r, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec), 2 * n)[:n]
    if not acf[0] > 0.0:
        return 1.0
    taus = 1.0 + 2.0 * np.cumsum(acf[1:] / acf[0])
    lags = np.arange(1, n)
    ok = np.flatnonzero(lags >= window * taus)
    tau = taus[ok[0]] if ok.size else taus[-1]
    return float(max(tau, 1.0))


def noise_per_effective_sample(residuals: list[np.ndarray], parameters: int) -> tuple[float, float]:
    """``(nu, tau)``: residual variance per *independent* sample of a least-squares fit, and its ``tau``.

    ``residuals`` are the weighted residual series of the fit (one per
    measured channel, each in time order). ``s^2 = sum r^2 / (M - p)`` is the
    usual residual variance (``M`` residuals, ``p`` fitted parameters);
    autocorrelated residuals carry fewer independent samples, ``M / tau``,
    so the noise that matches the least-squares cost's curvature is
    ``nu = tau * s^2`` (``tau`` of each channel from
    :func:`integrated_autocorrelation_time`, averaged with the channels'
    residual energies as weights). ``nu`` is 0 for an exact fit.
    """
    series = [np.asarray(r, float).ravel() for r in residuals]
    energy = np.array([float(np.sum(r**2)) for r in series])
    total = float(energy.sum())
    count = sum(r.size for r, e in zip(series, energy, strict=True) if e > 0.0)
    if not total > 0.0 or count <= parameters:
        return 0.0, 1.0
    tau = float(sum(e * integrated_autocorrelation_time(r) for r, e in zip(series, energy, strict=True)) / total)
    return tau * total / (count - parameters), tau
