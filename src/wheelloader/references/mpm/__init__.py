"""Plane-strain Material Point Method continuum reference plant (optional extra ``mpm``: Taichi).

:class:`MPMPlant` implements :class:`wheelloader.references.Plant`: ``dig(path, pile, soil, seed=0)``
returns a :class:`~wheelloader.estimator.CycleLog` with F_T, F_N, fill and the carved pile. The solver
(:mod:`.solver`) is a 2-D MLS-MPM with Hencky elasticity and Mohr-Coulomb plasticity with cohesion;
the bucket is a rigid kinematic tool of plates with Coulomb friction and adhesion. Importing this
package does not import Taichi; the first solver does (``pip install "wheelloader[mpm]"``).
:mod:`.newton_blade` runs the blade verification case in Newton's implicit MPM as a cross-check
(optional extra ``mpm-newton``).
"""

from ._backend import INSTALL_HINT, MPMUnavailableError, initialised_threads, taichi_available, taichi_module
from .plant import DEFAULT_RESOLUTION, MPMPlant, MPMSettings
from .scene import SceneSettings
from .soil import DEFAULT_YOUNGS_MODULUS, ContinuumSoil, jaky_poisson_ratio
from .tool import Plate, ToolShape, Trajectory, bucket_shape

__all__ = [
    "DEFAULT_RESOLUTION", "DEFAULT_YOUNGS_MODULUS", "INSTALL_HINT", "ContinuumSoil", "MPMPlant", "MPMSettings",
    "MPMUnavailableError", "Plate", "SceneSettings", "ToolShape", "Trajectory", "bucket_shape", "jaky_poisson_ratio",
    "initialised_threads", "taichi_available", "taichi_module",
]
