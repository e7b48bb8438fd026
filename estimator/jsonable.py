"""One conversion of results to JSON-ready Python values, used by every writer of the project."""

from __future__ import annotations

import json
import lzma
import math
from pathlib import Path
from typing import Any

import numpy as np


def to_jsonable(value: Any) -> Any:
    """A copy of ``value`` that ``json.dumps(..., allow_nan=False)`` accepts.

    Dicts (keys as strings), lists and tuples are converted recursively; NumPy arrays become lists,
    NumPy scalars Python numbers and booleans; paths become strings; objects with ``to_dict()`` (soil
    parameters, bucket, pile) are converted through it; non-finite floats (NaN, inf) become ``None``,
    since JSON has no such numbers and a reader must not mistake them for values.
    """
    if isinstance(value, dict):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, "to_dict") and callable(value.to_dict):
        return to_jsonable(value.to_dict())
    return value


def read_json(path: str | Path, error: type[Exception] | None = None) -> Any:
    """The JSON value in the file ``path`` (read through xz when it ends in ``.xz``), with one clear error for a
    file that is not JSON.

    Raises
    ------
    ParameterError (or ``error``)
        Not valid JSON, not UTF-8, a directory, or nested too deeply to read (Python's recursion limit).
    """
    from .errors import ParameterError

    error = error or ParameterError
    path = Path(path)
    try:
        if path.name.endswith(".xz"):  # a compressed sidecar of a saved cycle
            with lzma.open(path, "rt", encoding="utf-8-sig") as fh:
                return json.loads(fh.read())
        return json.loads(path.read_text(encoding="utf-8-sig"))
    except lzma.LZMAError as exc:
        raise error(f"{path}: not an xz file ({exc})") from None
    except json.JSONDecodeError as exc:
        raise error(f"{path}: not a valid JSON file ({exc})") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a valid JSON file (not UTF-8: {exc.reason} at byte {exc.start})") from None
    except IsADirectoryError:
        raise error(f"{path}: not a valid JSON file (a directory)") from None
    except RecursionError:
        raise error(f"{path}: not a valid JSON file (nested too deeply to read)") from None
