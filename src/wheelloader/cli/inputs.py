"""Reading what a command is given: soil parameters, piles, paths and cycle logs, with clear errors."""

from __future__ import annotations

import logging
import lzma
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the estimator (and scipy) is imported only when a command runs
    from wheelloader.estimator import Pile, SoilParams

#: Pile presets of ``--pile``.
PILE_PRESETS = ("trapezoid", "ideal_slope", "slope")


def load_pile(spec: str | None) -> Pile:
    """A :class:`Pile` from a JSON file (``{"x": [...], "z": [...]}`` or a cycle-log sidecar) or a preset
    name (``None``: the trapezoid)."""
    from wheelloader.estimator import ParameterError, Pile

    if spec is None or spec == "trapezoid":
        return Pile.trapezoid()
    if spec in ("slope", "ideal_slope"):
        return Pile.ideal_slope()
    path = Path(spec)
    if not path.exists():
        raise ParameterError(f"--pile {spec!r} is neither a file nor a preset ({', '.join(PILE_PRESETS)})")
    from wheelloader.estimator.jsonable import read_json

    data = read_json(path)
    if isinstance(data, dict) and isinstance(data.get("pile"), dict):
        data = data["pile"]  # a cycle-log sidecar
    try:
        pile = Pile.from_dict(data)
    except ParameterError as exc:
        raise ParameterError(f"{path}: {exc}") from None
    from wheelloader.estimator.plausibility import check_pile

    for warning in check_pile(pile, str(path)):
        logging.getLogger("wheelloader.cli").warning("warning: %s: %s", path, warning)
    return pile


def load_soil(spec: str) -> SoilParams:
    """Soil parameters from a params.json (as ``wheelloader calibrate`` writes it, or a bare 8-parameter
    JSON) or a soil preset name."""
    from wheelloader.estimator import PRESET_NAMES, ParameterError, preset

    path = Path(spec)
    if spec in PRESET_NAMES and not path.exists():
        return preset(spec)
    from wheelloader.estimator import load_params

    if path.exists() or path.suffix.lower() == ".json":
        if not path.exists():
            raise ParameterError(f"params file {spec} not found")
        if path.is_dir():
            raise ParameterError(f"params {spec} is a directory; give a params.json file")
        return load_params(path)
    try:
        return load_params(spec)
    except ParameterError:
        raise ParameterError(f"params {spec!r} is neither a file nor a soil preset ({', '.join(PRESET_NAMES)})"
                             ) from None


def is_cycle_log(path: Path) -> bool:
    """Whether ``path`` is a cycle-log CSV, plain or ``.csv.xz`` (its JSON sidecar beside it and F_T, F_N columns)."""
    if not path.name or not path.is_file() or not sidecar_of(path).exists():
        return False
    opener = lzma.open if path.name.endswith(".xz") else open
    try:
        with opener(path, "rt", encoding="utf-8-sig") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    header = [h.strip() for h in line.split(",")]
                    return "F_T" in header and "F_N" in header
    except (UnicodeDecodeError, lzma.LZMAError):
        return False  # reading it as a path CSV then reports the problem
    return False


def sidecar_of(csv_path: str | Path) -> Path:
    """The JSON sidecar of a cycle-log CSV (same stem; ``.json.xz`` beside a ``.csv.xz``)."""
    from wheelloader.estimator import ParameterError
    from wheelloader.estimator.cyclelog import sidecar_path

    if not Path(csv_path).name:
        raise ParameterError(f"{str(csv_path)!r} is not a file name")
    return sidecar_path(csv_path)


def add_strict_flag(parser: Any, help_text: str) -> None:
    """Add ``--strict`` to a subcommand's parser."""
    parser.add_argument("--strict", action="store_true", help=help_text)


def check_physical(soil: SoilParams, source: str, strict: bool) -> SoilParams:
    """``soil`` unchanged; its parameters outside the physical domain logged as a warning naming
    ``source``, or with ``strict`` a :class:`ParameterError`."""
    from wheelloader.estimator import ParameterError

    problems = soil.physical_warnings()
    if problems:
        text = f"{source}: parameters outside the physical domain: " + "; ".join(problems)
        if strict:
            raise ParameterError(text)
        logging.getLogger("wheelloader.cli").warning("warning: %s (--strict makes this an error)", text)
    return soil
