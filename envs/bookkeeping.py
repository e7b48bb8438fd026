"""The bookkeeping of a digging step, written once for every backend.

A step of the bucket moves the tip by ``(dx, dz)`` and ends at blade angle
``theta`` with soil forces ``F_T, F_N`` and a payload of weight ``W_load``.
Four places need what happens then, and they must agree:

* :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv` (Python floats),
* :class:`~wheelloader.envs.vector.BucketLoadingVectorEnv` (NumPy rows),
* :func:`~wheelloader.planner.verify_plan` (NumPy arrays along a path),
* the planner's NLP (:mod:`wheelloader.planner.trajectory`, CasADi expressions).

So the formulas live here, written with arithmetic and comparison operators
that Python floats, NumPy arrays and (where needed) CasADi expressions share;
the few operations that differ are keyword arguments, the way
:func:`~wheelloader.estimator.force_model.log_ngamma_slope` takes ``tan``:
``cos`` and ``sin`` (NumPy's by default; the single env passes ``math``'s,
the NLP CasADi's) and ``pos`` (``max(v, 0)``: :func:`exact_pos` by default,
a smooth version in the NLP).

Also here: the cycle-end rule (:func:`cycle_progress`, :func:`cycle_done`) and
the parser of ``reset(options=...)`` shared by both envs
(:func:`parse_reset_options`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from wheelloader.estimator import FLAG_OUT_OF_SOIL, ParameterError, SoilParams, as_soil
from wheelloader.estimator.checks import check_range

from .config import EnvConfig, RewardTerms, RewardWeights, check_relax
from .truth import as_truth

_new_terms = tuple.__new__

#: Keys accepted in ``reset(options=...)`` by both envs (the batched env also takes ``reset_mask``).
RESET_OPTIONS: tuple[str, ...] = ("keep_pile", "relax", "soil", "truth", "sensor_noise")


# ------------------------------------------------------------------ positive part
def exact_pos(v: Any) -> Any:
    """``max(v, 0)`` as ``(v + |v|) / 2``: the same expression for Python floats and NumPy arrays, exact
    for finite values (``v + v`` and halving are exact in binary floating point), without a branch."""
    return 0.5 * (v + abs(v))


# ------------------------------------------------------------------ energy
def step_work(f_t: Any, f_n: Any, dx: Any, dz: Any, blade_angle: Any, load_weight: Any, *,
              cos: Callable = np.cos, sin: Callable = np.sin, pos: Callable | None = None) -> tuple[Any, Any]:
    """Mechanical work of one step on the soil and on the payload [J].

    The tip displacement ``(dx, dz)`` [m] is resolved along the blade
    (``ds_t = dx cos(theta) + dz sin(theta)``) and across it
    (``ds_n = dz cos(theta) - dx sin(theta)``) at the step's end angle
    ``theta`` [rad]; only positive work counts (the loader does not recover
    energy):

    * on the soil: ``pos(F_T ds_t + F_N ds_n)``;
    * on the payload (lifting the soil in the bucket): ``pos(W_load dz)``.

    Parameters
    ----------
    f_t, f_n : float, numpy.ndarray or casadi.SX
        Soil forces at the step's end [N].
    dx, dz : same type
        Tip displacement of the step [m].
    blade_angle : same type
        Blade angle at the step's end [rad].
    load_weight : same type
        Weight of the soil in the bucket at the step's end, W_load [N].
    cos, sin : callable, keyword-only
        The backend's trigonometric functions (default NumPy's; ``math``'s are much faster on floats).
    pos : callable, optional, keyword-only
        The backend's ``max(v, 0)``; default :func:`exact_pos` (floats and NumPy arrays). The NLP passes a
        smooth one.

    Returns
    -------
    (soil, payload)
        Work on the soil and on the payload [J].
    """
    c, s = cos(blade_angle), sin(blade_angle)
    work = f_t * (dx * c + dz * s) + f_n * (dz * c - dx * s)
    lift = load_weight * dz
    if pos is None:
        return 0.5 * (work + abs(work)), 0.5 * (lift + abs(lift))  # exact_pos, inlined (the env's hot path)
    return pos(work), pos(lift)


# ------------------------------------------------------------------ reward
def outside_validity(depth: Any, flags: Any) -> Any:
    """Whether the tip is in soil (``depth > 0``) with a force-model flag other than "out of soil".

    Works on Python ints (a bool comes back) and on NumPy arrays (element-wise).
    """
    return (depth > 0.0) & ((flags & ~FLAG_OUT_OF_SOIL) != 0)


def reward_terms(weights: RewardWeights, capacity: float, max_push_force: float, max_lift_force: float,
                 fill_gain: Any, energy: Any, invalid: Any, stalled: Any, f_t: Any, f_n: Any
                 ) -> RewardTerms:
    """The five reward terms of a step (:class:`~wheelloader.envs.config.RewardTerms`).

    Parameters
    ----------
    weights : RewardWeights
        Weights of the terms.
    capacity : float
        Bucket capacity [m^3].
    max_push_force, max_lift_force : float
        The loader's force limits [N].
    fill_gain : float or numpy.ndarray
        Fill gained this step [m^3].
    energy : same type
        Work of the step on soil plus payload [J] (:func:`step_work`).
    invalid : bool or numpy.ndarray
        Tip in soil outside the model's validity domain (:func:`outside_validity`).
    stalled : bool or numpy.ndarray
        The step stalled.
    f_t, f_n : float or numpy.ndarray
        Plant forces at the step's end [N].

    Returns
    -------
    RewardTerms
        ``(fill, energy, validity, stall, force)``; the reward is their sum in this order
        (:meth:`RewardTerms.total`).
    """
    r_fill = weights.fill * fill_gain / capacity
    r_energy = -weights.energy * energy
    r_valid = 0.0 - weights.validity * invalid  # bools count 0 or 1 (and 0.0 - 0.0 is +0.0)
    r_stall = 0.0 - weights.stall * stalled
    soft = weights.force_soft_limit
    ex_t = f_t / max_push_force - soft
    ex_n = f_n / max_lift_force - soft
    excess = 0.5 * (ex_t + abs(ex_t)) + 0.5 * (ex_n + abs(ex_n))  # exact_pos of each, inlined
    r_force = -weights.force * excess
    return _new_terms(RewardTerms, (r_fill, r_energy, r_valid, r_stall, r_force))  # RewardTerms(...), faster


# ------------------------------------------------------------------ cycle end
def cycle_progress(touched: Any, entered: Any, in_soil: Any, fill: Any, min_fill: float) -> tuple[Any, Any]:
    """Update the two flags of the cycle-end rule after a sample.

    ``touched``: the tip has been in soil. ``entered``: it has been in soil
    with at least ``min_fill`` loaded (``fill`` and ``min_fill`` in the same
    unit: m^3 in the envs, a fraction of the capacity in
    :func:`~wheelloader.planner.verify.cycle_end_index`). Python bools or
    NumPy arrays.
    """
    return touched | in_soil, entered | (in_soil & (fill >= min_fill))


def cycle_done(touched: Any, entered: Any, z: Any, clearance: Any, crest: Any, exit_clearance: float) -> Any:
    """The cycle-end rule of the envs: out of the soil after loading.

    The cycle ends when the tip is more than ``exit_clearance`` [m] above the
    start-of-cycle surface (``clearance`` = tip z minus surface height) after
    it has ``entered`` the soil with enough loaded, or, having only
    ``touched`` the soil, once it is also more than ``exit_clearance`` above
    the pile's ``crest`` [m].
    """
    out_of_pile = entered | (touched & (z > crest + exit_clearance))
    return out_of_pile & (clearance > exit_clearance)


# ------------------------------------------------------------------ reset options
@dataclasses.dataclass(frozen=True)
class ResetRequest:
    """The parsed ``reset(options=...)`` of a bucket-loading env.

    Attributes
    ----------
    keep_pile : bool
        Start on the carved pile of the previous cycle.
    relax : bool or float
        Relax the kept pile (True: to the soil's friction angle; a float: to that repose angle [rad]).
    soil : None, str or SoilParams
        ``None`` (the configured behaviour), ``"keep"``, ``"resample"`` or a soil to use.
    config : EnvConfig
        The env settings after the options ``truth`` and ``sensor_noise``.
    config_changed : bool
        Whether ``truth`` or ``sensor_noise`` were given.
    """

    keep_pile: bool
    relax: bool | float
    soil: None | str | SoilParams
    config: EnvConfig
    config_changed: bool


def _check_keep_pile(value: Any) -> bool:
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    raise ParameterError(f"reset option keep_pile must be a bool, got {value!r}")


def _check_sensor_noise(value: Any) -> float:
    return check_range("reset option sensor_noise", value, 0.0)


def _check_soil(value: Any) -> None | str | SoilParams:
    if value is None or (isinstance(value, str) and value in ("keep", "resample")):
        return value
    try:
        return as_soil(value)
    except ParameterError as exc:
        raise ParameterError(f"reset option soil must be 'keep', 'resample' or a soil (preset name, SoilParams, "
                             f"parameter dict): {exc}") from None


def parse_reset_options(options: Mapping[str, Any] | None, cfg: EnvConfig) -> ResetRequest:
    """Validate ``reset(options=...)`` of either env (one parser, one set of messages).

    Parameters
    ----------
    options : dict or None
        Keys from :data:`RESET_OPTIONS`: ``keep_pile`` (bool), ``relax``
        (bool or repose angle in (0, pi/2) rad), ``soil`` (``"keep"``,
        ``"resample"`` or a soil), ``truth`` (:class:`TruthOptions` or dict)
        and ``sensor_noise`` (finite std >= 0 [N]). The batched env removes
        its ``reset_mask`` before calling this.
    cfg : EnvConfig
        The env's settings (defaults of ``keep_pile`` and ``relax``).

    Returns
    -------
    ResetRequest

    Raises
    ------
    ParameterError
        Naming the bad option and value.
    """
    if options is None:
        options = {}
    elif not isinstance(options, Mapping):
        raise ParameterError(f"reset options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(str(k) for k in set(options) - set(RESET_OPTIONS))
    if unknown:
        raise ParameterError(f"reset options: unknown key(s) {unknown}; expected some of {list(RESET_OPTIONS)}")
    changes: dict[str, Any] = {}
    if "truth" in options:
        changes["truth"] = as_truth(options["truth"])
    if "sensor_noise" in options:
        changes["sensor_noise"] = _check_sensor_noise(options["sensor_noise"])
    keep = _check_keep_pile(options["keep_pile"]) if "keep_pile" in options else cfg.keep_pile
    relax = check_relax(options["relax"], "reset option relax") if "relax" in options else cfg.relax
    soil = _check_soil(options.get("soil"))
    config = dataclasses.replace(cfg, **changes) if changes else cfg
    return ResetRequest(keep_pile=keep, relax=relax, soil=soil, config=config, config_changed=bool(changes))
