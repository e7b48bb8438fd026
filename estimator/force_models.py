"""The force models one argument selects: ``force_model=`` in calibrate, predict, the env and the planner.

========================  ===================================================================================
name                      model
========================  ===================================================================================
``"fee"``                 the paper's modified FEE (eqs 1-17); the bucket fill is the carved area capped at the
                          nominal capacity (or the logged fill); no force once the tip leaves the soil
``"fee-payload"``         the FEE with the payload as a state (:mod:`~wheelloader.estimator.payload`): in soil
                          the FEE with the carved fill as its surcharge; the kept soil (retention, smooth heaped
                          capacity) is the fill, and its weight and inertia take over from the surcharge as the
                          tip leaves the soil (the opt-in carried-load term, ``carried_in_soil=False``)
``"fee-learned"``         ``"fee-payload-depth"`` (:data:`LEARNED_BASE`; ``"fee-payload"`` up to weights v2) plus
                          a correction learned offline from the continuum (MPM) cycles,
                          with the soil among its inputs (:mod:`~wheelloader.estimator.learned`); its payload
                          is the one fitted with it (the shipped artifact's), unless given
``"fee-payload-depth"``   ``"fee-payload"`` with a depth-squared share of the soil's weight beside the wedge,
                          ``N_gamma + k`` in eq 1 (:attr:`~wheelloader.estimator.ModelOptions.wedge_offset`,
                          ``k =`` :data:`DEFAULT_WEDGE_OFFSET`, fitted offline to the continuum's training
                          cycles): a term of fixed shape carries the depth scaling that phi and a fake
                          cohesion carry in the FEE; no new parameter
========================  ===================================================================================

:data:`DEFAULT_PAYLOAD` is the payload fitted to the project's continuum cycles except the held-out soil
(dirt) and pile (25 deg): 254 MPM cycles of ``data/mpm`` and ``data/results/adaptation_mpm*/cycles``, by
``fit_payload`` (command in ``docs/guide/force_models.md``). It is a default for users; benchmarks that judge
the model refit it on their own training split.
"""

from __future__ import annotations

import functools
from dataclasses import replace

from .checks import check_choice
from .cyclelog import CycleLog
from .errors import ParameterError
from .kinematics import ContactState
from .payload import PayloadOptions, payload_contact_state
from .validity import DEFAULT_OPTIONS, ModelOptions

__all__ = ["DEFAULT_FORCE_MODEL", "DEFAULT_PAYLOAD", "DEFAULT_WEDGE_OFFSET", "DEPTH_MODELS", "FORCE_MODELS",
           "LEARNED_BASE", "PAYLOAD_MODELS", "PLANT_FORCE_MODELS", "check_force_model", "fee_options_for",
           "cycle_contact_state", "model_options_for"]

#: Names accepted by ``force_model=``.
FORCE_MODELS: tuple[str, ...] = ("fee", "fee-payload", "fee-learned", "fee-payload-depth")
#: The names the env and the planner take: all of them (the env evaluates ``"fee-learned"``'s correction with
#: :mod:`~wheelloader.estimator.learned_plant`, the planner with its CasADi twin
#: :func:`~wheelloader.estimator.learned.casadi_correction`).
PLANT_FORCE_MODELS: tuple[str, ...] = FORCE_MODELS
#: The models built on the payload state.
PAYLOAD_MODELS: tuple[str, ...] = ("fee-payload", "fee-learned", "fee-payload-depth")
DEFAULT_FORCE_MODEL = "fee"
#: The payload fitted to the continuum training cycles (module docstring); rounded to 4 digits.
DEFAULT_PAYLOAD = PayloadOptions(retention=0.9649, heap_factor=0.6059, sharpness=1.926)
#: ``"fee-payload-depth"``'s offset ``k`` of N_gamma (:attr:`ModelOptions.wedge_offset`), fitted to the training
#: loops of ``benchmarks/transfer.py`` (never to its test paths) by ``python benchmarks/model_form.py --fit-offset``
#: (``docs/results/model_form.md``).
DEFAULT_WEDGE_OFFSET = 2.0
#: The physical model ``"fee-learned"``'s correction sits on (weights v3 on; v1-v2 sat on ``"fee-payload"``).
LEARNED_BASE = "fee-payload-depth"
#: The models with ``"fee-payload-depth"``'s N_gamma offset.
DEPTH_MODELS: tuple[str, ...] = ("fee-payload-depth", "fee-learned")


def check_force_model(name: object, payload: PayloadOptions | None, error: type[Exception] = ParameterError
                      ) -> PayloadOptions | None:
    """Validate ``force_model``/``payload``; return the payload options the model uses (None for ``"fee"``)."""
    check_choice("force_model", name, FORCE_MODELS, error=error)
    if name == "fee":
        if payload is not None:
            raise error('payload options need force_model="fee-payload" (or "fee-learned", "fee-payload-depth")')
        return None
    if payload is None and name == "fee-learned":
        from .learned import default_learned_model

        return default_learned_model().payload
    if payload is None:
        return DEFAULT_PAYLOAD
    if not isinstance(payload, PayloadOptions):
        raise error(f"payload must be a PayloadOptions, got {type(payload).__name__}")
    return payload


def model_options_for(name: str, options: ModelOptions) -> ModelOptions:
    """The force-model options ``name`` needs on top of ``options`` (the payload's carried load)."""
    if name in DEPTH_MODELS:  # "fee-learned" is built on "fee-payload-depth" (its base, LEARNED_BASE)
        return replace(options, carried_load=True, carried_in_soil=False, wedge_offset=DEFAULT_WEDGE_OFFSET)
    return replace(options, carried_load=True, carried_in_soil=False) if name in PAYLOAD_MODELS else options


@functools.lru_cache(maxsize=8)
def fee_options_for(name: str) -> ModelOptions:
    """The FEE's options under model ``name`` without the carried load (the envs add that on their own): the paper's
    options, or ``"fee-payload-depth"``'s N_gamma offset."""
    return replace(model_options_for(name, DEFAULT_OPTIONS), carried_load=False)


def cycle_contact_state(log: CycleLog, name: str, payload: PayloadOptions | None, slope_window: float,
                        fill: str) -> ContactState:
    """A logged cycle's contact state under force model ``name`` (``fill`` applies to ``"fee"`` only)."""
    if name in PAYLOAD_MODELS:
        return payload_contact_state(log, payload, slope_window)
    return log.contact_state(slope_window, fill)

