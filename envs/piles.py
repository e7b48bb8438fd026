"""The piles of the bucket-loading envs: the ``pile`` argument, the toe and the nominal start pose on a pile.

Shared by the single and the batched env (through :mod:`wheelloader.envs.config`, which re-exports them) and by
the planner, whose cycles start where the env's do.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from wheelloader.estimator import ParameterError, Pile

__all__ = ["nominal_start_pose", "parse_pile", "pile_toe"]


def parse_pile(pile: Any) -> Pile:
    """Parse the ``pile`` argument: ``None`` (default trapezoid), a :class:`Pile`, or a dict
    ``{"shape": "trapezoid" | "ideal_slope", **builder_kwargs}`` (angles in radians)."""
    if pile is None:
        return Pile.trapezoid()
    if isinstance(pile, Pile):
        return pile
    if isinstance(pile, Mapping):
        kwargs = dict(pile)
        shape = kwargs.pop("shape", "trapezoid")
        builders = {"trapezoid": Pile.trapezoid, "ideal_slope": Pile.ideal_slope}
        if shape not in builders:
            raise ParameterError(f"pile shape must be one of {sorted(builders)}, got {shape!r}")
        try:
            return builders[shape](**kwargs)
        except TypeError as exc:
            raise ParameterError(f"pile: bad arguments for {shape!r}: {exc}") from None
    raise ParameterError(f"pile must be None, a Pile or a dict, got {type(pile).__name__}")


def pile_toe(pile: Pile) -> float:
    """x of the pile toe: the last node before the surface first rises above its minimum [m]."""
    return pile.x0 + pile.spacing * max(_first_rising(pile.heights) - 1, 0)


def nominal_start_pose(pile: Pile) -> tuple[float, float, float]:
    """The env's default start pose on ``pile``: 0.10 m before the toe, 0.03 m above the ground, blade
    at -5 deg (x [m], z [m], blade angle [rad]).

    The ground is the surface's minimum, or the highest surface from the pile's first node to the toe where
    that is higher: a carved pile whose floor dips below its first node (a plant's measured surface: a few
    mm of spill at the first node, a dip of one grid cell further on; the toe is then the first node) would
    otherwise start the tip inside the soil with the blade flat to it, outside the model's validity domain,
    and every plan on that pile failed its check (the MPM loop's sand piles 3-5, ``docs/results/loop_mpm.md``).
    """
    z = pile.heights
    ground = max(float(z.min()), float(z[: max(_first_rising(z), 1)].max()))
    return pile_toe(pile) - 0.10, ground + 0.03, math.radians(-5.0)


def _first_rising(z: np.ndarray) -> int:
    """Index of the first node above the surface's minimum (0 on a flat surface)."""
    rising = np.nonzero(z > z.min() + 1e-9)[0]
    return int(rising[0]) if rising.size else 0
