"""Figures shared by the demo and the command line (matplotlib is imported lazily)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator.paths import BucketPath
from wheelloader.estimator.pile import Pile


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "cairo") and not _has_display():
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _has_display() -> bool:
    import os

    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def plot_pile_and_paths(pile: Pile, paths: Sequence[BucketPath], ax: Any = None, carved: Sequence[Pile] = (),
                        x_range: tuple[float, float] | None = None) -> Any:
    """Pile surface (and carved surfaces) with tip paths, in metres, equal aspect."""
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    lo, hi = x_range or (pile.x0, min(pile.x_end, max(float(np.max(p.x)) for p in paths) + 0.5) if paths else
                         pile.x_end)
    xs = np.linspace(lo, hi, 600)
    ax.fill_between(xs, pile.surface_height(xs), -0.05, color="#c8a165", alpha=0.5, lw=0)
    ax.plot(xs, pile.surface_height(xs), color="#7a5c2e", lw=1.5, label="pile surface")
    top = pile.surface_height(xs)
    for k, surface in enumerate(carved):
        below = surface.surface_height(xs)
        ax.fill_between(xs, below, top, where=below < top - 1e-9, color=f"C{k + 3}", alpha=0.35, lw=0,
                        label=f"soil removed (cycle {k + 1})")
        top = below
    for path in paths:
        ax.plot(path.x, path.z, lw=1.8, label=path.name)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="upper left")
    return ax


def plot_forces(t: np.ndarray, series: dict[str, np.ndarray], ax: Any = None, ylabel: str = "force [kN]",
                styles: dict[str, str] | None = None) -> Any:
    """Force time series in kN (e.g. F_T, F_N, F_R measured and predicted)."""
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    styles = styles or {}
    for label, values in series.items():
        ax.plot(t, np.asarray(values) / 1e3, styles.get(label, "-"), lw=1.3, label=label)
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return ax


def save(fig: Any, path: str | Path) -> Path:
    """Save and close a figure."""
    path = Path(path)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    _pyplot().close(fig)
    return path


def new_figure(rows: int = 1, cols: int = 2, size: tuple[float, float] = (11, 4)) -> tuple[Any, Any]:
    """A new figure and axes."""
    plt = _pyplot()
    return plt.subplots(rows, cols, figsize=size)
