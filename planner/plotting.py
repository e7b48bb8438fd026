"""Figures of a planned cycle: path over the pile, forces against the limits, the Pareto front.

matplotlib is imported inside the functions (Agg backend when not already
on a file backend), so importing this module is cheap and never opens a window.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, Loader, Pile
from wheelloader.estimator.plotting import finish_figure

from .pareto import ParetoPoint


def _pyplot() -> Any:
    import matplotlib

    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo"):
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_plan(path: BucketPath, forces: dict[str, np.ndarray], pile: Pile, loader: Loader,
              out: str | Path | None = None, *, baseline: BucketPath | None = None,
              pareto: Sequence[ParetoPoint] | None = None, chosen_weight: float | None = None,
              baseline_point: tuple[float, float] | None = None,
              plan_point: tuple[float, float] | None = None, title: str | None = None) -> Any:
    """Plot a plan: pile and paths; F_T, F_N along the plan with the loader's limits; the Pareto front.

    Parameters
    ----------
    path : BucketPath
        The planned path (sampled at the control rate).
    forces : dict
        ``{"t", "F_T", "F_N"}`` [s, N, N] of the NumPy re-simulation along ``path``.
    pile : Pile
        Surface at the start of the cycle.
    loader : Loader
        Its force limits are drawn.
    out : str or Path, optional
        Where to save the figure (PNG); not saved when None.
    baseline : BucketPath, optional
        A comparison path (the paper's default Bezier path) drawn dashed.
    pareto : sequence of ParetoPoint, optional
        Adds a panel of fill [m^3] against energy [kJ]; points that failed the check are crosses,
        feasible ones IPOPT did not converge on are open circles.
    chosen_weight : float, optional
        Energy weight of the plan [1/kJ] (for the legend).
    baseline_point : (fill, energy), optional
        Fill [m^3] and energy [J] of the baseline path, drawn on the Pareto panel.
    plan_point : (fill, energy), optional
        Fill [m^3] and energy [J] of the plan itself, highlighted on the Pareto panel.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    plt = _pyplot()
    ncols = 3 if pareto else 2
    fig, axes = plt.subplots(1, ncols, figsize=(5.5 * ncols, 4.2))
    ax = axes[0]
    xs = pile.x
    ax.fill_between(xs, np.minimum(pile.heights.min(), 0.0), pile.heights, color="#c8a27a", alpha=0.6, label="pile")
    ax.plot(path.x, path.z, color="tab:blue", lw=2, label="planned path")
    lo, hi = float(path.x.min()), float(path.x.max())
    if baseline is not None:
        ax.plot(baseline.x, baseline.z, color="tab:gray", lw=1.5, ls="--", label=baseline.name or "baseline")
        lo, hi = min(lo, float(baseline.x.min())), max(hi, float(baseline.x.max()))
    ax.set_xlim(lo - 0.3, hi + 0.5)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal", adjustable="box")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("bucket tip path")

    ax = axes[1]
    t = np.asarray(forces["t"])
    ax.plot(t, np.asarray(forces["F_T"]) / 1e3, color="tab:blue", label="F_T (NumPy model)")
    ax.plot(t, np.asarray(forces["F_N"]) / 1e3, color="tab:orange", label="F_N (NumPy model)")
    ax.axhline(loader.max_push_force / 1e3, color="tab:blue", ls=":", lw=1, label="push limit")
    ax.axhline(loader.max_lift_force / 1e3, color="tab:orange", ls=":", lw=1, label="lift limit")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("force [kN]")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title("predicted forces along the plan")

    if pareto:
        ax = axes[2]
        good = [p for p in pareto if p.ok]
        bad = [p for p in pareto if not p.ok]
        optimal = [p for p in good if p.solver_ok]
        unproven = [p for p in good if not p.solver_ok]
        if optimal:
            ax.plot([p.energy / 1e3 for p in optimal], [p.fill for p in optimal], "o", color="tab:blue",
                    label="plans (IPOPT ok, check ok)")
        if unproven:
            ax.plot([p.energy / 1e3 for p in unproven], [p.fill for p in unproven], "o", mfc="none",
                    mec="tab:orange", label="check ok, IPOPT not converged")
        front = sorted((p for p in good if p.pareto_optimal), key=lambda p: p.energy)
        if front:
            ax.plot([p.energy / 1e3 for p in front], [p.fill for p in front], "-", color="tab:blue", lw=1,
                    label="Pareto front")
        for p in pareto:
            ax.annotate(f"{p.energy_weight:g}", (p.energy / 1e3, p.fill), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
        if bad:
            ax.plot([p.energy / 1e3 for p in bad], [p.fill for p in bad], "x", color="tab:red", ms=8,
                    label="failed the NumPy check")
        if plan_point is not None:
            label = "this plan" if chosen_weight is None else f"this plan (lambda = {chosen_weight:g}/kJ)"
            ax.plot(plan_point[1] / 1e3, plan_point[0], "s", mfc="none", mec="k", ms=11, label=label)
        if baseline_point is not None:
            ax.plot(baseline_point[1] / 1e3, baseline_point[0], "D", color="tab:gray", label="Bezier baseline")
        ax.set_xlabel("energy [kJ] (NumPy re-simulation)")
        ax.set_ylabel("fill [m^3]")
        ax.legend(loc="lower right", fontsize=8)
        ax.set_title("Pareto sweep over lambda [1/kJ]")
    return finish_figure(fig, out, title, dpi=110)
