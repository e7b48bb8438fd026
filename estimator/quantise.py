"""Fixed grids for what the planner receives, so that last-bit differences do not become different plans.

The calibrated soil differs between CPUs in its last bits: OpenBLAS picks other kernels (``SkylakeX``
on AVX-512 machines, ``Haswell`` on AVX2 ones) and NumPy other SIMD loops, and a least-squares solve
rounds differently. Measured on the demo: the soil differed by up to 5e-14 (relative; 2e-12 on another
cycle), and IPOPT grows such a difference about tenfold per iteration, so after 40-60 iterations another iterate passed
the NumPy check and another path was dug. The planner therefore plans with the soil rounded to a fixed
grid (:data:`SOIL_RELATIVE_STEP` of each parameter's upper paper bound) and on the pile rounded to
:data:`PILE_STEP`: a difference of 1e-12 then crosses a grid line only with a probability of about
1e-5 per value, and both grids lie far below what the model or a survey resolves.
"""

from __future__ import annotations

import numpy as np

from .pile import Pile
from .soil import PAPER_BOUNDS, PARAMETER_NAMES, SoilParams

#: Grid of the planner's soil: this fraction of each parameter's upper paper bound (gamma 2.3e-4 kg/m^3,
#: phi and delta 7.9e-8 rad, cohesion and adhesion 5 mPa, k_phi 0.5 N/m^(n+2), n 1.5e-7).
SOIL_RELATIVE_STEP = 1e-7
#: Grid of the planner's pile heights [m]: 1 micrometre.
PILE_STEP = 1e-6
#: Relative tolerance of the planner's near-tie decisions (which iterate, which fallback placement, which
#: calibration start wins): a candidate replaces the incumbent only when it is better by more than this
#: fraction of the larger magnitude; otherwise the earlier one in a fixed order stays.
TIE_RELATIVE = 1e-9


def soil_steps() -> dict[str, float]:
    """The grid step of each soil parameter (SI units)."""
    return {name: SOIL_RELATIVE_STEP * PAPER_BOUNDS[name][1] for name in PARAMETER_NAMES}


def quantise_soil(soil: SoilParams) -> SoilParams:
    """``soil`` rounded to the planner's grid (:data:`SOIL_RELATIVE_STEP` of each upper paper bound).

    A strictly positive parameter (gamma, n) stays positive: it is never rounded below one step.
    """
    values = {}
    for name, step in soil_steps().items():
        value = getattr(soil, name)
        q = float(np.round(value / step) * step)
        if value > 0.0 and q <= 0.0 and name in ("gamma", "n"):
            q = step
        values[name] = q
    return SoilParams(**values)


def quantise_heights(heights: np.ndarray, step: float = PILE_STEP) -> np.ndarray:
    """Heights rounded to ``step`` [m] (default :data:`PILE_STEP`)."""
    return np.round(np.asarray(heights, dtype=float) / step) * step


def quantise_pile(pile: Pile) -> Pile:
    """``pile`` with its heights rounded to :data:`PILE_STEP` (the same grid, x0 and spacing)."""
    return pile.with_heights(quantise_heights(pile.heights))


def better(candidate: float, incumbent: float, rtol: float = TIE_RELATIVE) -> bool:
    """Whether ``candidate`` is smaller than ``incumbent`` by more than ``rtol`` of the larger magnitude.

    The near-tie rule of the planner and the calibration's start selection: within the tolerance the
    incumbent (the earlier in a fixed order) stays, whatever the last bits say.
    """
    if not np.isfinite(candidate):
        return False
    if not np.isfinite(incumbent):
        return True
    return bool(candidate < incumbent - rtol * max(abs(candidate), abs(incumbent)))
