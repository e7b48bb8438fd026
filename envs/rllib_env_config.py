"""Construction from an ``env_config`` mapping, the way RLlib builds envs, beside Gymnasium's keywords.

RLlib calls an env class with its ``env_config`` (a dict, or RLlib's ``EnvContext``, a dict subclass that
also carries ``worker_index``) as the *first positional* argument; Gymnasium passes keyword arguments.
:func:`accepts_env_config` lets one ``__init__`` take both: a mapping in the first positional place is
unpacked into keyword arguments, merged with those given as keywords. A key the env does not know, or a
key given both ways with different values, raises :class:`~wheelloader.estimator.ParameterError` naming it.
The decorated ``__init__`` keeps its signature (``inspect.signature`` follows ``__wrapped__``).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from wheelloader.estimator import ParameterError

__all__ = ["accepts_env_config", "merge_env_config"]


def _same(a: Any, b: Any) -> bool:
    if a is b:
        return True
    try:
        return bool(a == b)
    except (TypeError, ValueError):  # e.g. arrays: ambiguous truth value
        return False


def merge_env_config(config: Mapping[str, Any], kwargs: Mapping[str, Any], known: Iterable[str],
                     owner: str) -> dict[str, Any]:
    """``config`` (an env_config mapping) merged with keyword arguments ``kwargs``.

    Raises
    ------
    ParameterError
        A key of ``config`` not in ``known``, a non-string key, or a key in both with different values.
    """
    known = set(known)
    merged: dict[str, Any] = {}
    for key, value in config.items():
        if not isinstance(key, str):
            raise ParameterError(f"{owner}: env_config keys must be argument names (str), got {key!r}")
        merged[key] = value
    unknown = sorted(set(merged) - known)
    if unknown:
        raise ParameterError(f"{owner}: unknown env_config key(s) {unknown}; known keys: {sorted(known)}")
    for key, value in kwargs.items():
        if key in merged and not _same(merged[key], value):
            raise ParameterError(f"{owner}: {key!r} given twice with different values, {merged[key]!r} in "
                                 f"env_config and {value!r} as a keyword argument")
        merged[key] = value
    return merged


def accepts_env_config(known: Callable[[], Iterable[str]] | None = None,
                       defaults: Callable[[dict[str, Any]], dict[str, Any]] | None = None) -> Callable:
    """Decorate an env's ``__init__`` so that its first positional argument may be an env_config mapping.

    Parameters
    ----------
    known : callable, optional
        Returns the accepted keys; default: the names of ``__init__``'s parameters (for an ``__init__``
        with ``**kwargs``, pass the names it forwards too).
    defaults : callable, optional
        ``defaults(merged) -> merged``: settings that apply only when built from an env_config (e.g. the
        episode limit that ``gym.make`` would otherwise add as a wrapper).
    """

    def decorate(init: Callable[..., None]) -> Callable[..., None]:
        params = [p for name, p in inspect.signature(init).parameters.items() if name != "self"]
        named = [p.name for p in params if p.kind not in (inspect.Parameter.VAR_KEYWORD,
                                                          inspect.Parameter.VAR_POSITIONAL)]

        @functools.wraps(init)
        def wrapper(self: Any, *args: Any, **kwargs: Any) -> None:
            if args and isinstance(args[0], Mapping):
                owner = type(self).__name__
                if len(args) > 1:
                    raise ParameterError(f"{owner}: after an env_config mapping pass settings as keywords, "
                                         f"got {len(args) - 1} more positional argument(s)")
                names = set(known()) if known is not None else set(named)
                merged = merge_env_config(args[0], kwargs, names, owner)
                if defaults is not None:
                    merged = defaults(merged)
                return init(self, **merged)
            return init(self, *args, **kwargs)

        return wrapper

    return decorate
