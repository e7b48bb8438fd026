"""Fit-quality verdict: could the cycle's data determine the soil?

:attr:`Calibration.success` is the optimiser's word (it converged). It says
nothing about whether the data could pin the soil down: all-zero, constant
or absurd forces, pure noise and an unfit model all converge. The verdict
checks the data and the fit against the criteria below; every one that
fires is a :class:`FitWarning` with a stable ``code``, and the fit is
*trustworthy* when none fires.

=======================  ====================================================================
code                     fires when (in-soil samples)
=======================  ====================================================================
``not_converged``        the optimiser did not converge (``success`` is False)
``too_few_samples``      fewer than :data:`MIN_TRUSTED_SAMPLES` samples are in soil
``forces_near_zero``     the mean measured |F_R| is below :data:`FORCE_FLOOR` [N]
``forces_implausible``   the largest measured |F_R| exceeds :data:`FORCE_CEILING` [N]
``constant_forces``      |F_R| varies by less than :data:`MIN_RELATIVE_VARIATION` of its mean
``large_error``          the F_R RMSE exceeds :data:`MAX_ERROR_PERCENT` of the mean |F_R|
``unexplained``          the model explains less than :data:`MIN_EXPLAINED` of the forces'
                         variation about their mean (R^2 over F_T and F_N together)
``parameters_on_bounds`` :data:`MAX_PARAMETERS_ON_BOUNDS` or more parameters sit on a bound that
                         is not a natural zero (any upper bound; the lower bounds of gamma and n)
=======================  ====================================================================

The thresholds are fixed, not tuned per case. On noise-free and noisy
(5-20 % white noise) synthetic cycles of the presets the fit explains >= 55 %
of the variation (>= 92 % at 5 %) with F_R errors <= 37 % (<= 11 % at 5 %);
pure noise, SNR 0.1-1, all-zero, constant and 1e30 forces land far beyond them.
A true soil with two or more parameters at the edges of the bounds cannot be
told from data that pull beyond them: about 3 % of soils drawn uniformly from
the bounds are flagged ``parameters_on_bounds``. The FEE fits the DEM reference
cycles of ``data/reference`` poorly (R^2 0.03-0.29, F_R error 36-123 %): they
come back untrustworthy, which is what the verdict is for.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Fewest in-soil samples of a trustworthy fit (about 0.8 s of digging at 60 Hz).
MIN_TRUSTED_SAMPLES = 50
#: Smallest mean measured |F_R| over the in-soil samples [N].
FORCE_FLOOR = 10.0
#: Largest measured |F_R| a bucket can see [N] (100 MN; no loader pushes that hard).
FORCE_CEILING = 1e8
#: Smallest standard deviation of |F_R| relative to its mean: below, the forces carry no shape.
MIN_RELATIVE_VARIATION = 0.01
#: Largest F_R RMSE in % of the mean measured |F_R| (FitQuality.percent_r).
MAX_ERROR_PERCENT = 50.0
#: Smallest share of the forces' variation the model explains (R^2).
MIN_EXPLAINED = 0.5
#: Number of parameters on non-natural bounds that makes the fit untrustworthy.
MAX_PARAMETERS_ON_BOUNDS = 2
#: Fit-vector parameters whose lower bound is a natural value (no cohesion, adhesion, sinkage
#: pressure or friction), so sitting there is no sign of trouble.
NATURAL_LOWER = ("cohesion", "adhesion", "phi", "delta", "K")


@dataclass(frozen=True)
class FitWarning:
    """One reason why a calibration may not have determined the soil.

    Attributes
    ----------
    code : str
        Stable name (module docstring table).
    message : str
        What was measured, in words and numbers.
    """

    code: str
    message: str

    def __str__(self) -> str:
        return f"{self.code}: {self.message}"

    def to_dict(self) -> dict[str, str]:
        """``{"code": ..., "message": ...}``."""
        return {"code": self.code, "message": self.message}


def explained_share(obs_t, obs_n, pred_t, pred_n) -> float:
    """R^2 of the stacked (F_T, F_N) prediction: 1 - SSR / (variation about each channel's mean); NaN if constant."""
    obs_t, obs_n, pred_t, pred_n = (np.asarray(v, dtype=float) for v in (obs_t, obs_n, pred_t, pred_n))
    ss_res = float(np.sum((obs_t - pred_t) ** 2) + np.sum((obs_n - pred_n) ** 2))
    ss_tot = float(np.sum((obs_t - obs_t.mean()) ** 2) + np.sum((obs_n - obs_n.mean()) ** 2))
    return 1.0 - ss_res / ss_tot if ss_tot > 0.0 else float("nan")


def assess(*, success: bool, obs_t, obs_n, pred_t, pred_n, percent_r: float, names, values, lower,
           upper) -> list[FitWarning]:
    """The warnings of one fit (module docstring); an empty list means trustworthy.

    Parameters
    ----------
    success : bool
        The optimiser's convergence.
    obs_t, obs_n, pred_t, pred_n : array_like
        Measured and fitted F_T, F_N on the in-soil samples [N].
    percent_r : float
        F_R RMSE in % of the mean measured |F_R| (:class:`FitQuality`).
    names : sequence of str
        Fit-vector names (:data:`~wheelloader.estimator.soil_vector.SOIL_VECTOR_NAMES`).
    values, lower, upper : array_like
        Fit vector and its bounds.
    """
    warnings: list[FitWarning] = []
    obs_t = np.asarray(obs_t, dtype=float)
    obs_n = np.asarray(obs_n, dtype=float)
    count = int(obs_t.size)
    if not success:
        warnings.append(FitWarning("not_converged", "the optimiser did not converge"))
    if count < MIN_TRUSTED_SAMPLES:
        warnings.append(FitWarning("too_few_samples", f"{count} samples in soil, fewer than {MIN_TRUSTED_SAMPLES}"))
    f_r = np.hypot(obs_t, obs_n)
    mean_r = float(np.mean(f_r)) if count else 0.0
    if mean_r < FORCE_FLOOR:
        warnings.append(FitWarning("forces_near_zero",
                                   f"mean measured |F_R| {mean_r:.3g} N is below {FORCE_FLOOR:g} N"))
    peak = float(np.max(f_r)) if count else 0.0
    if peak > FORCE_CEILING:
        warnings.append(FitWarning("forces_implausible",
                                   f"measured |F_R| reaches {peak:.3g} N, above {FORCE_CEILING:.0e} N"))
    if mean_r > 0.0 and float(np.std(f_r)) < MIN_RELATIVE_VARIATION * mean_r:
        warnings.append(FitWarning("constant_forces", f"|F_R| varies by {float(np.std(f_r)) / mean_r:.2%} of "
                                   f"its mean, less than {MIN_RELATIVE_VARIATION:.0%}: no shape to fit"))
    if not percent_r <= MAX_ERROR_PERCENT:
        warnings.append(FitWarning("large_error",
                                   f"F_R RMSE is {percent_r:.3g} % of the mean |F_R|, above {MAX_ERROR_PERCENT:g} %"))
    r2 = explained_share(obs_t, obs_n, pred_t, pred_n)
    if not r2 >= MIN_EXPLAINED:
        txt = "nothing (the forces do not vary)" if not np.isfinite(r2) else f"{max(r2, -9.99):.0%}"
        warnings.append(FitWarning("unexplained", f"the model explains {txt} of the forces' variation, "
                                   f"less than {MIN_EXPLAINED:.0%}"))
    values, lower, upper = (np.asarray(v, dtype=float) for v in (values, lower, upper))
    span = upper - lower
    tol = 1e-7 * np.where(span > 0.0, span, 1.0)
    on = []
    for i, name in enumerate(names):
        if span[i] <= 0.0:
            continue  # fixed by the caller
        if values[i] >= upper[i] - tol[i]:
            on.append(f"{name} (upper)")
        elif values[i] <= lower[i] + tol[i] and name not in NATURAL_LOWER:
            on.append(f"{name} (lower)")
    if len(on) >= MAX_PARAMETERS_ON_BOUNDS:
        warnings.append(FitWarning("parameters_on_bounds", "the data pull " + ", ".join(on) + " onto the bounds"))
    return warnings
