"""Basics shared by the SB3 training and evaluation scripts in ``train/`` (not a library module).

The scripts import the modules of this folder by name (Python puts the
script's folder first on ``sys.path``; pytest has it on its ``pythonpath``). By role:

* ``common``: the env id, set-up names, JSON output, torch threads, argparse types;
* ``setups``: the training VecEnv (the packaged SB3 adapter
  :mod:`wheelloader.envs.sb3`) and the two training set-ups;
* ``policies``: baseline policies and SB3 models behind one ``reset`` / ``act`` interface;
* ``rollouts``: episodes, summaries, evaluation of several policies;
* ``curves``: the learning-curve callback and plot;
* ``training``: the shared training arguments and the training run of ``ppo.py`` / ``sac.py``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from wheelloader.estimator import PRESET_NAMES, as_soil
from wheelloader.estimator.jsonable import to_jsonable
from wheelloader.provenance import machine_info

__all__ = ["DEFAULT_PLANT_SOIL", "ENV_ID", "SETUPS", "int_list", "machine_info", "set_torch_threads",
           "str_list", "weights", "write_json"]

#: The env trained and evaluated on (one digging cycle, 600 steps at 60 Hz).
ENV_ID = "wheelloader/BucketLoading-v0"
#: Soil used as "the plant" of the digital-twin set-up by default.
DEFAULT_PLANT_SOIL = "lean_clay"
#: Set-ups of the training scripts.
SETUPS = ("randomized", "twin")


def set_torch_threads(threads: int) -> int:
    """Set torch's intra-op threads (1 by default: small MLPs gain nothing from more on a shared 2-core CPU)."""
    import torch

    if threads < 1:
        raise ValueError(f"--torch-threads must be >= 1, got {threads!r}")
    torch.set_num_threads(threads)
    return torch.get_num_threads()


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON (creates the folder)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(data), indent=2, allow_nan=False) + "\n")


# ------------------------------------------------------------------ argparse types
def int_list(text: str) -> list[int]:
    """``"0,1,2"`` or ``"0-4"`` -> list of ints."""
    text = text.strip()
    if "-" in text and "," not in text and not text.startswith("-"):
        lo, hi = (int(v) for v in text.split("-", 1))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",") if v.strip()]


def str_list(text: str) -> list[str]:
    """Comma-separated names; ``"all"`` = every soil preset."""
    if text.strip().lower() == "all":
        return list(PRESET_NAMES)
    names = [v.strip() for v in text.split(",") if v.strip()]
    for n in names:
        as_soil(n)  # validates (ParameterError names the bad preset)
    return names


def weights(text: str) -> dict[str, float]:
    """``"stall=0.2,validity=0.001"`` -> dict (validated by the env's RewardWeights)."""
    from wheelloader.envs import RewardWeights

    out: dict[str, float] = {}
    for item in text.split(","):
        if item.strip():
            key, _, value = item.partition("=")
            out[key.strip()] = float(value)
    RewardWeights(**out)
    return out
