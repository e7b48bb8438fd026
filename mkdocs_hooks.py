"""MkDocs hook of the documentation site (``mkdocs.yml``): the package as the API reference sees it.

The installed package maps ``wheelloader`` to ``src/wheelloader`` and its three layers to the top-level
``estimator/``, ``envs/`` and ``planner/`` folders (``pyproject.toml``'s ``package-dir``). mkdocstrings reads
sources, not the installed package, so before a build this lays that layout out as symbolic links under
``build/api-src/wheelloader`` (ignored by git), the one path ``mkdocs.yml`` gives mkdocstrings.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent
LAYERS = ("estimator", "envs", "planner")


def api_source_tree(root: Path = ROOT) -> Path:
    """(Re)build ``build/api-src/wheelloader``: links to ``src/wheelloader``'s entries and the layers."""
    package = root / "build" / "api-src" / "wheelloader"
    if package.exists() or package.is_symlink():
        shutil.rmtree(package)
    package.mkdir(parents=True)
    for entry in sorted((root / "src" / "wheelloader").iterdir()):
        if entry.name != "__pycache__":
            (package / entry.name).symlink_to(entry, target_is_directory=entry.is_dir())
    for layer in LAYERS:
        (package / layer).symlink_to(root / layer, target_is_directory=True)
    return package


def on_config(config: Any) -> Any:
    """MkDocs entry point: lay out the tree again (a later ``mkdocs serve`` rebuild sees new modules)."""
    api_source_tree(Path(config.config_file_path).resolve().parent)
    return config


# MkDocs loads this file while it reads mkdocs.yml, before any plugin's ``on_config``: mkdocstrings drops a
# search path that does not exist yet, so the tree is laid out here, once, for a fresh clone's first build.
api_source_tree()
