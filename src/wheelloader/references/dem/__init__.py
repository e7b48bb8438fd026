"""The Yade DEM reference: a quasi-2D slab pile of spheres dug by a kinematically driven rigid bucket.

Yade is a system package (``bash dem/install_yade.sh``); without it :func:`run_scenario` raises
:class:`YadeNotFoundError` naming the install command. See ``README.md`` in this folder for the scenario, and
``wheelloader dem --help`` for the command line.

* :mod:`.config`: :class:`DemConfig`, the scaled paths, the tiny CI scenario;
* :mod:`.runner`: :func:`run_scenario` (Yade as a subprocess) and the conversion to cycle logs;
* :mod:`.plant`: :class:`DEMPlant`, the scenario as a plant of the adaptation loop (any carved pile);
* :mod:`.reference_set`: the shipped reference set (cases, generation, manifest, loading, sanity).
"""

from ..filtering import DEFAULT_FILTER, filtered, moving_average, relative_noise, smooth
from .config import (
    BACK_HEIGHT,
    SOILS,
    TOP_PLATE,
    YADE_INSTALL,
    DemConfig,
    DemRunError,
    YadeNotFoundError,
    dual_cycle_paths,
    scenario_paths,
    tiny_config,
    tiny_path,
    write_path_csv,
)
from .plant import DEMPlant
from .reference_set import (
    MASS_TOLERANCE,
    REFERENCE_DIR,
    ReferenceCase,
    ReferenceRun,
    generate_reference,
    load_reference,
    reference_cases,
    regenerate_command,
    run_reference,
    sanity_figures,
    sanity_report,
    update_manifest,
    write_reference,
)
from .runner import DEFAULT_CACHE, DemRun, find_yade, read_raw, read_raw_cycle, run_scenario, scenario_script

__all__ = [
    "BACK_HEIGHT", "DEFAULT_CACHE", "DEFAULT_FILTER", "MASS_TOLERANCE", "REFERENCE_DIR", "SOILS", "TOP_PLATE",
    "YADE_INSTALL", "DEMPlant", "DemConfig", "DemRun", "DemRunError", "ReferenceCase", "ReferenceRun",
    "YadeNotFoundError",
    "dual_cycle_paths", "filtered", "find_yade", "generate_reference", "load_reference", "moving_average",
    "read_raw", "read_raw_cycle", "reference_cases", "regenerate_command", "relative_noise", "run_reference",
    "run_scenario", "sanity_figures", "sanity_report", "scenario_paths", "scenario_script", "smooth", "tiny_config",
    "tiny_path", "update_manifest", "write_path_csv", "write_reference",
]
