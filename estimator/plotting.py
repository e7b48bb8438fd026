"""Plots of calibrations and predictions in the style of the paper's Figs. 6 and 7.

matplotlib is imported inside the functions (Agg backend when saving), so
importing this module is cheap and never opens a window.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .calibration import Calibration, Prediction
from .cyclelog import CycleLog


def _pyplot():
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_path(ax: Any, path, pile, pile_after=None, label: str | None = None) -> Any:
    """Tip path in the x-z plane over the pile surface (Fig. 6 left)."""
    xs = pile.x
    ax.fill_between(xs, np.minimum(pile.heights.min(), 0.0), pile.heights, color="#c8a27a", alpha=0.6, label="pile")
    if pile_after is not None:
        ax.plot(pile_after.x, pile_after.heights, color="#7a5230", lw=1, ls="--", label="surface after")
    ax.plot(path.x, path.z, color="tab:blue", lw=2, label=label or path.name)
    lo, hi = min(path.x.min(), 0.0) - 0.3, path.x.max() + 0.5
    ax.set_xlim(lo, hi)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="upper left", fontsize=8)
    return ax


def plot_calibration(cycle: CycleLog, calibrations: Calibration | list[Calibration], out: str | Path | None = None,
                     title: str | None = None) -> Any:
    """Fig. 6 style: path (left) and observed vs predicted F_R over time (right), one line per method.

    A multi-stage calibration adds Fig. 7 style panels: stage 1 (F_T) and
    stage 2 (observed, filtered and computed FEE force F).
    """
    plt = _pyplot()
    cals = [calibrations] if isinstance(calibrations, Calibration) else list(calibrations)
    multi = next((c for c in cals if c.method == "multi-stage"), None)
    ncols = 2 if multi is None else 4
    fig, axes = plt.subplots(1, ncols, figsize=(5.5 * ncols, 4.2))
    plot_path(axes[0], cycle.path, cycle.pile, cycle.pile_after)
    t = cycle.path.t
    ax = axes[1]
    ax.plot(t, cycle.resultant, color="0.5", lw=1, label="observed F_R")
    for cal in cals:
        pr = np.hypot(cal.predicted_tangential, cal.predicted_normal)
        ax.plot(t, pr, lw=1.6, label=f"{cal.method} ({cal.quality.percent_r:.1f} %)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("F_R [N]")
    ax.legend(fontsize=8)
    ax.set_title("resultant force")
    if multi is not None:
        idx = np.flatnonzero(multi.in_soil)
        s1 = axes[2]
        s1.plot(t, cycle.tangential, color="0.5", lw=1, label="observed F_T")
        s1.plot(t[idx], multi.predicted_tangential[idx], lw=1.6, label="final model F_T")
        s1.set_title("multi-stage: F_T (Fig. 7a)")
        s1.set_xlabel("t [s]")
        s1.set_ylabel("F_T [N]")
        s1.legend(fontsize=8)
        s2 = axes[3]
        delta = multi.params.delta
        f_obs = cycle.normal / np.cos(delta)
        from scipy.ndimage import gaussian_filter1d

        sigma = float(multi.settings.get("sigma", 3.0))
        s2.plot(t, f_obs, color="0.6", lw=1, label="F_obs = F_N/cos(delta*)")
        if sigma > 0:
            s2.plot(t, gaussian_filter1d(f_obs, sigma, mode="nearest"), color="k", lw=1, label="filtered")
        s2.plot(t, multi.predicted_normal / np.cos(delta), lw=1.6, label="computed F")
        s2.set_title("multi-stage: FEE force F (Fig. 7b)")
        s2.set_xlabel("t [s]")
        s2.set_ylabel("F [N]")
        s2.legend(fontsize=8)
    return finish_figure(fig, out, title)


def plot_prediction(prediction: Prediction, pile=None, out: str | Path | None = None, title: str | None = None) -> Any:
    """Path (left) and predicted (and observed, when known) F_T, F_N, F_R over time (right)."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    if pile is not None:
        plot_path(axes[0], prediction.path, pile)
    else:
        axes[0].plot(prediction.path.x, prediction.path.z)
        axes[0].set_xlabel("x [m]")
        axes[0].set_ylabel("z [m]")
    t = prediction.path.t
    ax = axes[1]
    if prediction.observed_tangential is not None:
        ax.plot(t, np.hypot(prediction.observed_tangential, prediction.observed_normal), color="0.5", lw=1,
                label="observed F_R")
    ax.plot(t, prediction.resultant, lw=1.8, label="predicted F_R")
    ax.plot(t, prediction.tangential, lw=1, ls="--", label="predicted F_T")
    ax.plot(t, prediction.normal, lw=1, ls=":", label="predicted F_N")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("force [N]")
    if prediction.quality is not None:
        ax.set_title(f"F_R RMSE {prediction.quality.rmse_r:.0f} N ({prediction.quality.percent_r:.1f} %)")
    ax.legend(fontsize=8)
    return finish_figure(fig, out, title)


def finish_figure(fig: Any, out: str | Path | None = None, title: str | None = None, dpi: int = 120) -> Any:
    """Add the title, lay out, and with ``out`` save the figure there and close it; return the figure."""
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if out is not None:
        fig.savefig(out, dpi=dpi)
        plt.close(fig)
    return fig
