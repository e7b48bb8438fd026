"""wheelloader: soil-force estimation, environments and planning for wheel-loader excavation.

Subpackages
-----------
wheelloader.estimator
    The modified Fundamental Earthmoving Equation, geometry, cycle logs and
    calibration of the soil parameters from one bucket-loading cycle.
wheelloader.envs
    Gymnasium environments on the same force model (``import
    wheelloader.envs`` registers them).
wheelloader.planner
    CasADi trajectory optimisation and MPC for the next cycle's path.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("wheelloader")
except PackageNotFoundError:  # pragma: no cover - running from a source tree without install
    __version__ = "0.0.0"

__all__ = ["__version__"]
