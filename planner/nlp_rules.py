"""This process's rules for the planner's NLPs (:mod:`.nlp`): whether the NLPs of one margin family stay in memory
side by side, and whether IPOPT solvers use compiled derivatives a compiled run left on this machine."""

from __future__ import annotations

from wheelloader.estimator import PlanningError

__all__ = ["RULES", "compiled_if_present", "hold_margin_variants"]

#: This process's memory rule for the NLPs (:func:`hold_margin_variants`) and its use of compiled derivatives
#: found on disk (:func:`compiled_if_present`).
RULES = {"hold_margin_variants": True, "compiled_if_present": False}


def compiled_if_present(use: bool) -> bool:
    """Whether IPOPT solvers of ``compiled=False`` settings evaluate the NLP's derivatives from the compiled
    library that a ``compiled=True`` run left on this machine (:func:`.codegen.present_by_key`, found by the NLP's
    key, so never a stale one) when it is there; returns the previous rule. Nothing is ever compiled for it:
    without the library the solver differentiates in CasADi's virtual machine as before. The derivatives are the
    same numbers either way, so the plans are too. ``wheelloader demo`` turns it on."""
    if not isinstance(use, bool):
        raise PlanningError(f"use must be True or False, got {use!r}")
    previous = RULES["compiled_if_present"]
    RULES["compiled_if_present"] = use
    return previous


def hold_margin_variants(hold: bool) -> bool:
    """Whether the NLPs of one margin family (the plan's and the wider-margin re-plans' of
    :func:`~wheelloader.planner.cycle.cautious_options`) stay in memory side by side; returns the previous rule.

    ``True`` (the default): each is built once per process. ``False``: a variant takes the place of the NLP of
    its family in memory (one of them at a time, ~150 MB each for 40 intervals), and the next solve of the other
    builds it again (the same plans, bit for bit, at ~1.3-1.6 s of CPU per build): ``wheelloader demo``'s memory
    budget. Measured on the replayed MPM loop (``benchmarks/between_cycles.py``): a re-planned cycle made the next
    cycle rebuild its plan's NLP, the longest time between cycles after the re-plan itself.
    """
    if not isinstance(hold, bool):
        raise PlanningError(f"hold must be True or False, got {hold!r}")
    previous = RULES["hold_margin_variants"]
    RULES["hold_margin_variants"] = hold
    return previous
