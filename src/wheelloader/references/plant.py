"""The interface every reference plant implements."""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from wheelloader.estimator import BucketPath, CycleLog, Pile, SoilParams


@runtime_checkable
class Plant(Protocol):
    """Something that digs a path and reports what happened.

    Attributes
    ----------
    name : str
        Short label for tables and metadata ("mpm", "dem", "fee-env").
    """

    name: str

    def dig(self, path: BucketPath, pile: Pile, soil: SoilParams | str, *, seed: int = 0) -> CycleLog:
        """Dig ``path`` into ``pile`` of ``soil``.

        Parameters
        ----------
        path : BucketPath
            Bucket-tip path (t, x, z, blade angle) in the project's conventions.
        pile : Pile
            Surface when the cycle starts (a carved pile for later cycles).
        soil : SoilParams or str
            The soil (a preset name or parameters); each plant documents which fields it uses.
        seed : int
            Seed of everything random in the plant (packing, jitter).

        Returns
        -------
        CycleLog
            ``tangential``/``normal`` [N] for the plant's bucket width, ``fill_volume`` [m^3] per
            sample, ``pile`` the surface it started on, ``pile_after`` the carved surface, and
            ``metadata`` with the plant's name, settings and cost.
        """
        ...
