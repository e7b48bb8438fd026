"""The reference plants by name: the one place that turns a plant's name and settings into a plant.

``wheelloader demo --plant``, the adaptation benchmarks' ``--plant`` and any script choose their plant here, so
that a new plant (or a new setting of one) is added once.
"""

from __future__ import annotations

from typing import Any

from wheelloader.estimator import ParameterError

from .plant import Plant

#: Names :func:`make_plant` knows: the FEE env (the model's own world), the MPM continuum, the Yade DEM.
PLANT_NAMES: tuple[str, ...] = ("fee-env", "mpm", "dem")
#: DEM scenarios of :func:`make_plant`: the default scenario, or the CI smoke test's coarse spheres.
DEM_SCENARIOS: tuple[str, ...] = ("default", "ci")


def make_plant(name: str, **settings: Any) -> Plant:
    """A reference plant by name.

    Parameters
    ----------
    name : str
        One of :data:`PLANT_NAMES`.
    **settings
        The plant's settings:

        * ``"fee-env"``: :class:`~wheelloader.references.fee_env.FEEEnvPlant`'s keywords (``keep_env``, env
          keyword arguments such as ``sensor_noise`` or ``truth``);
        * ``"mpm"``: :class:`~wheelloader.references.mpm.MPMPlant`'s keywords (``resolution`` [m], ``threads``
          and the other :class:`~wheelloader.references.mpm.MPMSettings` fields, ``bucket``); Taichi (the
          ``mpm`` extra) is needed when it digs, not here;
        * ``"dem"``: ``scenario`` (:data:`DEM_SCENARIOS`: ``"default"``, :class:`~wheelloader.references.dem.DemConfig`,
          or ``"ci"``, :func:`~wheelloader.references.dem.tiny_config`'s coarse spheres), other
          :class:`~wheelloader.references.dem.DemConfig` fields (``threads``, ...), and
          :class:`~wheelloader.references.dem.DEMPlant`'s keywords (``cache_dir``, ``work_dir``, ``timeout``,
          ``progress``; default progress: silent). Yade is needed when it digs, not here.

    Returns
    -------
    Plant
        A fresh plant.

    Raises
    ------
    ParameterError
        For an unknown name, DEM scenario or setting.
    """
    if name == "fee-env":
        from .fee_env import FEEEnvPlant

        return FEEEnvPlant(**settings)
    if name == "mpm":
        from .mpm import MPMPlant

        try:
            return MPMPlant(**settings)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"plant 'mpm': {exc}") from None
    if name == "dem":
        return _dem_plant(**settings)
    raise ParameterError(f"unknown plant {name!r}; choose from {', '.join(PLANT_NAMES)}")


def _dem_plant(scenario: str = "default", cache_dir: Any = None, work_dir: Any = None, timeout: float | None = None,
               progress: Any = None, **config: Any) -> Plant:
    """:func:`make_plant`'s ``"dem"``."""
    from .dem import DemConfig, DEMPlant, tiny_config

    if scenario not in DEM_SCENARIOS:
        raise ParameterError(f"plant 'dem': scenario must be one of {DEM_SCENARIOS}, got {scenario!r}")
    unknown = sorted(set(config) - set(DemConfig.__dataclass_fields__))
    if unknown:
        raise ParameterError(f"plant 'dem': unknown setting(s) {unknown}; expected DemConfig fields or "
                             "scenario, cache_dir, work_dir, timeout, progress")
    dem_config = tiny_config(**config) if scenario == "ci" else DemConfig(**config)
    return DEMPlant(dem_config, cache_dir=cache_dir, work_dir=work_dir, timeout=timeout,
                    progress=progress if progress is not None else _silent)


def _silent(line: str) -> None:
    """The DEM plant's default progress: nothing (a module function, so that the plant pickles)."""
