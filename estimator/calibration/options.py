"""Settings of a calibration: :class:`CalibrationOptions`, and the method names.

One frozen dataclass holds every setting of :func:`~wheelloader.estimator.calibration.calibrate`; it is
validated when it is made (``__post_init__``), so a bad setting fails before any work starts, and the
method name is canonicalised there once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..checks import check_choice, check_int, check_optional_int, check_range
from ..errors import CalibrationError, ParameterError
from ..force_model import DEFAULT_OPTIONS, ModelOptions
from ..force_models import DEFAULT_FORCE_MODEL, check_force_model, model_options_for
from ..kinematics import DEFAULT_SLOPE_WINDOW
from ..payload import PayloadOptions
from ..soil import SoilParams, as_soil, validate_bounds
from .fitmodel import MIN_SAMPLES
from .identify import HeldPrior
from .priors import class_prior

__all__ = ["DEFAULT_METHOD", "METHODS", "METHOD_ALIASES", "CalibrationOptions", "canonical_method"]

#: Calibration methods, by what they are.
METHODS: tuple[str, ...] = ("varpro", "single-stage", "multi-stage")
#: Other accepted names of the methods (case-insensitive): ``"default"`` is the varpro method.
METHOD_ALIASES: dict[str, str] = {"default": "varpro", "single": "single-stage", "multi": "multi-stage"}
#: The method :func:`calibrate` uses unless told otherwise.
DEFAULT_METHOD = "varpro"
#: Where the bucket load comes from (``fill``) and which residuals the prediction band's noise model fits
#: (``band_noise``).
FILL_SOURCES: tuple[str, ...] = ("log", "model")
BAND_NOISE_SOURCES: tuple[str, ...] = ("training", "cross-cycle")


def canonical_method(method: str) -> str:
    """The name in :data:`METHODS` of a method or alias; :class:`CalibrationError` if unknown."""
    key = method.strip().lower() if isinstance(method, str) else None
    if key in METHODS:
        return key
    if key in METHOD_ALIASES:
        return METHOD_ALIASES[key]
    raise CalibrationError(f"unknown calibration method {method!r}; choose one of {list(METHODS)} "
                           f"(aliases {sorted(METHOD_ALIASES)})")


def _coerce_initial(initial: Any) -> SoilParams | None:
    if initial is None or isinstance(initial, SoilParams):
        return initial
    params = getattr(initial, "params", None)  # a Calibration (not imported here: result.py imports this module)
    if isinstance(params, SoilParams):
        return params
    try:
        return as_soil(initial)
    except ParameterError as exc:
        raise CalibrationError(f"initial: {exc}") from None


def _check_weights(forgetting: Any, cycle_weights: Any) -> tuple[float, ...] | None:
    """Validate ``forgetting`` and ``cycle_weights`` (their count is checked against the cycles later)."""
    if forgetting is not None and cycle_weights is not None:
        raise CalibrationError("give forgetting or cycle_weights, not both")
    if forgetting is not None:
        check_range("forgetting", forgetting, 0.0, 1.0, low_open=True, error=CalibrationError)
    if cycle_weights is None:
        return None
    try:
        w = tuple(float(v) for v in cycle_weights)
    except (TypeError, ValueError):
        raise CalibrationError(f"cycle_weights must be numbers > 0, got {cycle_weights!r}") from None
    if not w or not all(math.isfinite(v) and v > 0.0 for v in w):
        raise CalibrationError(f"cycle_weights must be finite numbers > 0 (one per cycle), got {cycle_weights!r}")
    return w


@dataclass(frozen=True)
class CalibrationOptions:
    """Settings of :func:`~wheelloader.estimator.calibration.calibrate` (SI units), validated when made.

    Parameters
    ----------
    method : str
        ``"varpro"`` (our variable-projection method; alias ``"default"``), ``"single-stage"`` or
        ``"multi-stage"`` (the paper's, Section III; aliases ``"single"``, ``"multi"``). Stored canonical.
    initial : Calibration, SoilParams, dict or str, optional
        Warm start: the previous cycle's result. The varpro method refines it as one more start (besides
        its grid search); the paper's methods start from it instead of the mid-range guess. Its share of
        k_c/b in K is kept when K is split into k_c, k_phi. Stored as :class:`~wheelloader.estimator.SoilParams`.
    bounds : dict, optional
        ``name -> (lower, upper)`` for some of the eight parameters; the others keep the paper's bounds
        (eq 19j). Equal bounds fix a parameter. Stored with all eight filled in.
    lam : float
        Weight lambda of F_T in eq 19a, in [0, 1] (default 0.5; the multi-stage method uses its own stage
        weights).
    sigma : float
        Stage-2 Gaussian filter standard deviation [samples] (multi-stage), >= 0 and at most the cycle's
        sample count.
    grid : tuple of int
        Grid sizes over (phi, delta, n) (varpro method).
    n_starts : int
        Grid local minima refined (varpro method).
    max_iter : int, optional
        Iteration limit: L-BFGS-B ``maxiter`` per stage for the paper's methods (default 1000, as the
        paper); residual evaluations per refinement for the varpro method (default 100).
    model_options : ModelOptions
        Force-model options (the opt-in terms need the varpro method).
    slope_window : float
        Half-width of the local slope chord [m].
    min_samples : int
        Smallest number of in-soil samples accepted.
    regularize : bool
        Varpro method only: after the exact least-squares fit, take the MAP estimate under a weak prior
        (mean ``initial`` or the mid-range of the bounds, standard deviation range / sqrt(12)) with the noise
        per independent sample estimated from the residuals' autocorrelation
        (:mod:`wheelloader.estimator.calibration.varpro`, step 6).
    forgetting : float, optional
        Several cycles: forgetting factor ``f`` in (0, 1]; cycle ``k`` of ``N`` (oldest first) weighs
        ``f ** (N - 1 - k)`` in the cost (the newest 1). Default: every cycle weighs 1.
    cycle_weights : tuple of float, optional
        Several cycles: explicit weight of each cycle's squared residuals (instead of ``forgetting``).
    fill : {"log", "model"}
        Where the bucket load ``W_load`` comes from: ``"log"`` (default) the logged fill or load when the log
        has one, ``"model"`` the model's own bookkeeping (carving the pile along the path), the quantity a
        prediction of a new path has (:meth:`~wheelloader.estimator.CycleLog.contact_state`).
    prior : str or dict, optional
        Varpro method: the MAP estimate under a literature prior of the soil class being dug,
        ``"granular"`` or ``"cohesive"`` (paper Tables A1, A2;
        :mod:`wheelloader.estimator.calibration.priors`), or ``{name: (low, high)}`` ranges of your own
        over the fit vector; it replaces the weak prior of ``regularize``.
    force_model : str
        The model fitted (:data:`~wheelloader.estimator.force_models.FORCE_MODELS`): ``"fee"`` (default, the
        paper's FEE) or ``"fee-payload"`` (the FEE with the payload as a state: its kept soil is carried
        once the tip leaves the soil; varpro method; the fill follows the carving, whatever ``fill`` says).
    payload : PayloadOptions, optional
        The payload's parameters for ``"fee-payload"`` (default
        :data:`~wheelloader.estimator.force_models.DEFAULT_PAYLOAD`; fit your own with
        :func:`~wheelloader.estimator.payload.fit_payload`).
    band_noise : {"training", "cross-cycle"}
        Residual noise model of the prediction band (:mod:`~.bands`): ``"training"`` (default) fits it to the
        training residuals; ``"cross-cycle"`` (several cycles) to the residuals of each cycle predicted by a
        fit on the others (leave one cycle out; one local refinement per cycle).
    held : HeldPrior, optional
        Fit only what the cycles identify (varpro method; :mod:`~.identify`): the parameters free for the
        number of cycles given are fitted, the others held at the prior's mean (fixed, or a Gaussian prior of
        its width). Not with ``prior``.
    band_scale : float
        Factor (> 0, default 1) on the prediction band's standard deviation (:mod:`~.bands`): a band whose width
        was calibrated on validation paths (``benchmarks/transfer.py``) is wider than the training residuals
        say, since a new path is predicted worse than the cycle the soil was fitted to.

    Raises
    ------
    CalibrationError
        On any bad setting (unknown method, bad bounds or initial guess, a setting out of its range, a
        setting the chosen method does not have); :class:`~wheelloader.estimator.ParameterError` for a
        ``slope_window`` that is not > 0.
    """

    method: str = DEFAULT_METHOD
    initial: Any = None
    bounds: dict[str, tuple[float, float]] | None = None
    lam: float = 0.5
    sigma: float = 3.0
    grid: tuple[int, int, int] = (9, 9, 8)
    n_starts: int = 3
    max_iter: int | None = None
    model_options: ModelOptions = DEFAULT_OPTIONS
    slope_window: float = DEFAULT_SLOPE_WINDOW
    min_samples: int = MIN_SAMPLES
    regularize: bool = False
    forgetting: float | None = None
    cycle_weights: tuple[float, ...] | None = None
    fill: str = "log"
    prior: str | dict | None = None
    band_noise: str = "training"
    force_model: str = DEFAULT_FORCE_MODEL
    payload: PayloadOptions | None = None
    held: HeldPrior | None = None
    band_scale: float = 1.0

    def __post_init__(self) -> None:
        err = CalibrationError
        set_ = object.__setattr__
        set_(self, "method", canonical_method(self.method))
        set_(self, "cycle_weights", _check_weights(self.forgetting, self.cycle_weights))
        check_choice("fill", self.fill, FILL_SOURCES, error=err)
        set_(self, "payload", check_force_model(self.force_model, self.payload, error=err))
        if not isinstance(self.model_options, ModelOptions):
            raise err(f"model_options must be a ModelOptions, got {type(self.model_options).__name__}")
        set_(self, "model_options", model_options_for(self.force_model, self.model_options))
        if self.model_options.extra_terms and self.method != "varpro":
            raise err(f"the paper's methods fit the paper's model only; the opt-in term(s) "
                      f"{list(self.model_options.extra_terms)} need the varpro method")
        try:
            set_(self, "bounds", validate_bounds({} if self.bounds is None else self.bounds))
        except ParameterError as exc:
            raise err(str(exc)) from None
        check_range("lam", self.lam, 0.0, 1.0, error=err)
        check_range("sigma", self.sigma, 0.0, None, error=err)
        check_optional_int("max_iter", self.max_iter, error=err)
        if not (isinstance(self.grid, (tuple, list)) and len(self.grid) == 3):
            raise err(f"grid must be three positive integers (points over phi, delta, n), got {self.grid!r}")
        set_(self, "grid", tuple(check_int(f"grid[{k}]", g, error=err) for k, g in enumerate(self.grid)))
        check_int("n_starts", self.n_starts, error=err)
        check_int("min_samples", self.min_samples, error=err)
        check_range("slope_window", self.slope_window, 0.0, None, low_open=True, error=ParameterError)
        if not isinstance(self.regularize, bool):
            raise err(f"regularize must be True or False, got {self.regularize!r}")
        check_choice("band_noise", self.band_noise, BAND_NOISE_SOURCES, error=err)
        if self.prior is not None:
            class_prior(self.prior)  # raises CalibrationError on an unknown class or bad ranges
            if self.method != "varpro":
                raise err("a literature prior needs the varpro method")
        if self.held is not None:
            if not isinstance(self.held, HeldPrior):
                raise err(f"held must be a HeldPrior, got {type(self.held).__name__}")
            if self.method != "varpro" or self.prior is not None:
                raise err("held needs the varpro method and no prior (it is the prior)")
        check_range("band_scale", self.band_scale, 0.0, None, low_open=True, error=err)
        set_(self, "initial", _coerce_initial(self.initial))

    @property
    def max_nfev(self) -> int:
        """Residual evaluations per varpro refinement (``max_iter`` or 100)."""
        return self.max_iter or 100

    @property
    def maxiter(self) -> int:
        """L-BFGS-B iterations per stage of the paper's methods (``max_iter`` or 1000)."""
        return self.max_iter or 1000

    @property
    def map_estimate(self) -> bool:
        """Whether the varpro fit ends in a MAP estimate (``regularize`` or a literature ``prior``)."""
        return self.regularize or self.prior is not None or (
            self.held is not None and any(v > 0.0 for v in (self.held.std or {}).values()))
