"""Literature priors per soil class for the MAP calibration (``calibrate(..., prior="granular")``).

Where the data cannot decide a direction, the exact least-squares fit stops wherever the search
leaves it, often on a bound (n = 1.53, phi = 0). A prior of the soil class being dug holds it near
what such soils are: an independent Gaussian per fit-vector parameter (gamma, C, C_a, phi, delta, K,
n) whose mean and standard deviation are the moments of a uniform distribution over the range the
paper's appendix reports for the class (mean = mid-range, std = range / sqrt(12)), the same rule as
the weak prior of :mod:`~wheelloader.estimator.calibration.varpro` with literature ranges in place of
the calibration bounds. The noise weight ``nu`` is estimated from the exact fit's residuals and their
autocorrelation (:func:`~wheelloader.estimator.calibration.uncertainty.noise_per_effective_sample`).

Classes (paper Tables A1 and A2)
--------------------------------
``"granular"``: gravels and sands (USCS GW, GP, GM, GC, SW, SP, SM, SC): density 1297-2371 kg/m^3,
cohesion 0-3 kPa (GC-CL at most), no adhesion beyond that, internal friction 32-40 deg, external
friction 20 deg (steel, Broms/NAVFAC) to 0.83 phi (USACE) = 20-33 deg, Bekker exponent of the sands of
Table A2 0.71-1.15.

``"cohesive"``: silts and clays (ML, CL, CH, OL, OH, MH): density 1297-1500 kg/m^3 (Table A1 rows
1300-1500), cohesion and adhesion 0-48 kPa (soft to stiff cohesive soil), internal friction 22-33 deg,
external friction 2/3 phi to 0.83 phi = 15-27 deg, Bekker exponent of the clays 0.11-0.5.

K = k_c / b + k_phi gets no prior: Table A2 spans two orders of magnitude and K trades off against n.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import CalibrationError
from ..soil_vector import SOIL_VECTOR_NAMES

_DEG = math.pi / 180.0

#: Literature range per soil class and fit-vector parameter (SI; angles in rad): ``(low, high)``.
SOIL_CLASS_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "granular": {"gamma": (1297.0, 2371.0), "cohesion": (0.0, 3000.0), "adhesion": (0.0, 3000.0),
                 "phi": (32.0 * _DEG, 40.0 * _DEG), "delta": (20.0 * _DEG, 33.0 * _DEG), "n": (0.71, 1.15)},
    "cohesive": {"gamma": (1297.0, 1500.0), "cohesion": (0.0, 48_000.0), "adhesion": (0.0, 48_000.0),
                 "phi": (22.0 * _DEG, 33.0 * _DEG), "delta": (15.0 * _DEG, 27.0 * _DEG), "n": (0.11, 0.5)},
}

#: Names of the soil classes with a literature prior.
SOIL_CLASSES: tuple[str, ...] = tuple(SOIL_CLASS_RANGES)


def class_prior(prior: str | dict) -> tuple[np.ndarray, np.ndarray]:
    """``(mean, std)`` over the fit vector (std 0: no prior on that parameter) of a class or a range mapping.

    Parameters
    ----------
    prior : str or dict
        A name of :data:`SOIL_CLASSES`, or ``{fit-vector name: (low, high)}`` ranges of your own.
    """
    if isinstance(prior, str):
        key = prior.strip().lower()
        if key not in SOIL_CLASS_RANGES:
            raise CalibrationError(f"unknown soil class prior {prior!r}; choose one of {list(SOIL_CLASSES)} "
                                   "or give {name: (low, high)}")
        ranges = SOIL_CLASS_RANGES[key]
    elif isinstance(prior, dict):
        ranges = prior
    else:
        raise CalibrationError(f"prior must be a soil class name or a dict of ranges, got {type(prior).__name__}")
    mean = np.zeros(len(SOIL_VECTOR_NAMES))
    std = np.zeros(len(SOIL_VECTOR_NAMES))
    for name, pair in ranges.items():
        if name not in SOIL_VECTOR_NAMES:
            raise CalibrationError(f"prior: unknown parameter {name!r}; expected some of {list(SOIL_VECTOR_NAMES)}")
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise CalibrationError(f"prior[{name!r}] must be a pair (low, high), got {pair!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise CalibrationError(f"prior[{name!r}] must be finite with high > low, got {(lo, hi)!r}")
        i = SOIL_VECTOR_NAMES.index(name)
        mean[i], std[i] = 0.5 * (lo + hi), (hi - lo) / math.sqrt(12.0)
    return mean, std
