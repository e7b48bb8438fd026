"""Filters and noise measures of reference force records (the paper compared with filtered forces).

Reference forces are noisy (single particles jam at the cutting edge in the DEM; grid-crossing ripple
in the MPM). Compare against :func:`smooth` (a Gaussian filter, :data:`DEFAULT_FILTER`) and report
unfiltered figures too; :func:`relative_noise` measures the noise level.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from wheelloader.estimator import CycleLog, ParameterError

#: The filter used for comparisons with reference forces: Gaussian, sigma 0.1 s (FWHM 0.24 s).
DEFAULT_FILTER: dict[str, Any] = {"kind": "gaussian", "sigma_s": 0.1, "mode": "nearest"}


def smooth(values: np.ndarray, rate: float = 60.0, sigma_s: float = DEFAULT_FILTER["sigma_s"]) -> np.ndarray:
    """Gaussian filter of a 60 Hz force record (``scipy.ndimage.gaussian_filter1d``, mode 'nearest')."""
    from scipy.ndimage import gaussian_filter1d

    if not (rate > 0 and sigma_s > 0):
        raise ParameterError(f"rate and sigma_s must be > 0, got {rate!r}, {sigma_s!r}")
    return gaussian_filter1d(np.asarray(values, dtype=float), sigma_s * rate, mode="nearest")


def moving_average(values: np.ndarray, rate: float = 60.0, window_s: float = 0.25) -> np.ndarray:
    """Centred moving average over ``window_s`` (shrinking at the ends)."""
    v = np.asarray(values, dtype=float)
    half = max(1, int(round(0.5 * window_s * rate)))
    c = np.concatenate([[0.0], np.cumsum(v)])
    idx = np.arange(v.size)
    lo = np.clip(idx - half, 0, v.size)
    hi = np.clip(idx + half + 1, 0, v.size)
    return (c[hi] - c[lo]) / (hi - lo)


def relative_noise(values: np.ndarray, rate: float = 60.0, window_s: float = 0.25) -> float:
    """RMS of the deviation from a ``window_s`` moving average, relative to the RMS of that average."""
    v = np.asarray(values, dtype=float)
    m = moving_average(v, rate, window_s)
    denom = float(np.sqrt(np.mean(m**2)))
    return float(np.sqrt(np.mean((v - m) ** 2)) / denom) if denom > 0 else 0.0


def filtered(log: CycleLog, sigma_s: float = DEFAULT_FILTER["sigma_s"]) -> CycleLog:
    """The same log with Gaussian-filtered F_T and F_N (metadata records the filter)."""
    rate = 1.0 / float(np.median(np.diff(log.path.t)))
    meta = dict(log.metadata, filter={"kind": "gaussian", "sigma_s": sigma_s, "mode": "nearest"})
    return replace(log, tangential=smooth(log.tangential, rate, sigma_s), normal=smooth(log.normal, rate, sigma_s),
                   metadata=meta)
