"""Reference plants: worlds that are not the force model, to judge it by.

A *plant* digs a bucket path in a pile of some soil and reports what a machine would have measured:
:meth:`Plant.dig` returns a :class:`~wheelloader.estimator.CycleLog` (path, F_T, F_N, fill, the pile
before and after). :func:`make_plant` builds one by name. The FEE env is the model's own world; the plants
here are not:

* :mod:`wheelloader.references.mpm`: a plane-strain Material Point Method continuum with Mohr-Coulomb
  plasticity (optional extra ``mpm``: Taichi);
* :mod:`wheelloader.references.dem`: the Yade DEM (``wheelloader dem``; the system package ``yade``).
"""

from .plant import Plant
from .registry import DEM_SCENARIOS, PLANT_NAMES, make_plant

__all__ = ["DEM_SCENARIOS", "PLANT_NAMES", "Plant", "make_plant"]
