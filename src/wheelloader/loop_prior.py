"""The loop's calibration prior at the nominal soil (issue #32 item 4): which parameters one cycle can identify.

:class:`LoopPrior` holds gamma, K and n softly at the soil preset the user names and fits the rest; the
``ours`` strategy of :mod:`wheelloader.adaptation` takes it as ``Calibrating(prior=)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wheelloader.estimator import SoilParams, WheelloaderError
from wheelloader.estimator.calibration import HeldPrior
from wheelloader.estimator.checks import check_range
from wheelloader.estimator.soil_vector import SOIL_VECTOR_NAMES, soil_vector

#: Priors of the ``ours`` strategy's calibration (:class:`LoopPrior`): ``"none"`` fits all seven fit-vector
#: parameters freely; ``"nominal"`` holds gamma, K and n near the nominal soil (:class:`LoopPrior`).
PRIOR_NAMES: tuple[str, ...] = ("none", "nominal")
#: The ``ours`` strategy's default prior (``wheelloader demo --prior``, ``benchmarks/adaptation.py --prior``).
DEFAULT_PRIOR = "none"


@dataclass(frozen=True)
class LoopPrior:
    """The soft prior of the loop's calibration at the nominal soil (issue #32 item 4).

    One cycle cannot identify gamma, K and n (their Sobol total indices are <= 0.08 over the training
    families, ``docs/results/identify.md``): on one path they trade off against phi, and the best-cost fit
    lands at bounds and is wrong at another depth. With ``mode="nominal"`` they are held by a Gaussian prior
    (MAP, varpro method) at the nominal soil's values, and only ``free`` is fitted freely.

    Parameters
    ----------
    mode : str
        A name of :data:`PRIOR_NAMES`.
    gamma_rel, k_rel : float
        Prior standard deviation of gamma and of K = k_c / b + k_phi, relative to the nominal value (> 0).
    n_std : float
        Prior standard deviation of the sinkage exponent n (> 0).
    free : tuple of str
        Fit-vector parameters fitted freely (the Sobol rule's identifiable set).
    phi_std, delta_std : float
        Prior standard deviation of phi and delta [rad] where they are not in ``free`` (0: held fixed at the
        nominal value).
    cohesion_std, adhesion_std : float
        Prior standard deviation of the cohesion and the adhesion [Pa] where they are not in ``free`` (0: held
        fixed at the nominal value).
    """

    mode: str = "none"
    gamma_rel: float = 0.10
    k_rel: float = 0.30
    n_std: float = 0.15
    free: tuple[str, ...] = ("cohesion", "adhesion", "phi", "delta")
    phi_std: float = 0.0
    delta_std: float = 0.0
    cohesion_std: float = 0.0
    adhesion_std: float = 0.0

    def __post_init__(self) -> None:
        if self.mode not in PRIOR_NAMES:
            raise WheelloaderError(f"prior must be one of {PRIOR_NAMES}, got {self.mode!r}")
        for name in ("gamma_rel", "k_rel", "n_std"):
            check_range(name, getattr(self, name), 0.0, None, low_open=True, error=WheelloaderError)
        for name in ("phi_std", "delta_std", "cohesion_std", "adhesion_std"):
            check_range(name, getattr(self, name), 0.0, None, error=WheelloaderError)
        object.__setattr__(self, "free", tuple(self.free))

    def held(self, nominal: SoilParams, edge_thickness: float) -> HeldPrior | None:
        """The calibration's :class:`~wheelloader.estimator.calibration.HeldPrior` at ``nominal`` (None: no
        prior)."""
        if self.mode == "none":
            return None
        mean = dict(zip(SOIL_VECTOR_NAMES, soil_vector(nominal, edge_thickness).tolist(), strict=True))
        std = {"gamma": self.gamma_rel * mean["gamma"], "K": self.k_rel * mean["K"], "n": self.n_std}
        std |= {name: width for name, width in (("phi", self.phi_std), ("delta", self.delta_std),
                                                ("cohesion", self.cohesion_std), ("adhesion", self.adhesion_std))
                if width > 0.0}
        return HeldPrior(mean, std=std, free_one=self.free)


#: The loop's prior with every parameter held softly at the nominal soil (``"held"``): gamma, K and n as
#: ``"nominal"``, phi and delta within 5 deg, cohesion and adhesion within 1 kPa (one standard deviation), none
#: fitted freely. On the committed MPM loops (``docs/results/loop_mpm.md``, seed 0, ours' cycles 1-4 of gravel
#: and sand, each fit planned with on the next cycle's pile) one cycle's fit with ``"none"`` or ``"nominal"``
#: put phi at 0-5 or 45 deg (its bounds) and the adhesion at up to 7.4 kPa for these cohesionless soils; with
#: ``"held"`` phi stayed at 34-45 deg and the cohesion and adhesion below 2.3 kPa, and 8 of 8 plans passed
#: their check (``"nominal"`` 7, phi and delta within 3 deg and 300 Pa 6).
HELD_PRIOR = LoopPrior("nominal", free=(), phi_std=math.radians(5.0), delta_std=math.radians(5.0),
                       cohesion_std=1000.0, adhesion_std=1000.0)
#: Named loop priors of the plant benchmarks (``benchmarks/plant_adaptation.py --prior``).
LOOP_PRIORS: dict[str, LoopPrior] = {"none": LoopPrior("none"), "nominal": LoopPrior("nominal"), "held": HELD_PRIOR}


def loop_prior(prior: str | LoopPrior) -> LoopPrior:
    """The :class:`LoopPrior` of a name of :data:`LOOP_PRIORS` (or ``prior`` itself)."""
    if isinstance(prior, LoopPrior):
        return prior
    if prior not in LOOP_PRIORS:
        raise WheelloaderError(f"prior must be one of {tuple(LOOP_PRIORS)} or a LoopPrior, got {prior!r}")
    return LOOP_PRIORS[prior]
