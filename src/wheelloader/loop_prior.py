"""The loop's calibration prior at the nominal soil (issue #32 item 4): which parameters one cycle can identify.

:class:`LoopPrior` holds gamma, K and n softly at the soil preset the user names and fits the rest; the
``ours`` strategy of :mod:`wheelloader.adaptation` takes it as ``Calibrating(prior=)``.
"""

from __future__ import annotations

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
    """

    mode: str = "none"
    gamma_rel: float = 0.10
    k_rel: float = 0.30
    n_std: float = 0.15
    free: tuple[str, ...] = ("cohesion", "adhesion", "phi", "delta")

    def __post_init__(self) -> None:
        if self.mode not in PRIOR_NAMES:
            raise WheelloaderError(f"prior must be one of {PRIOR_NAMES}, got {self.mode!r}")
        for name in ("gamma_rel", "k_rel", "n_std"):
            check_range(name, getattr(self, name), 0.0, None, low_open=True, error=WheelloaderError)
        object.__setattr__(self, "free", tuple(self.free))

    def held(self, nominal: SoilParams, edge_thickness: float) -> HeldPrior | None:
        """The calibration's :class:`~wheelloader.estimator.calibration.HeldPrior` at ``nominal`` (None: no
        prior)."""
        if self.mode == "none":
            return None
        mean = dict(zip(SOIL_VECTOR_NAMES, soil_vector(nominal, edge_thickness).tolist(), strict=True))
        std = {"gamma": self.gamma_rel * mean["gamma"], "K": self.k_rel * mean["K"], "n": self.n_std}
        return HeldPrior(mean, std=std, free_one=self.free)
