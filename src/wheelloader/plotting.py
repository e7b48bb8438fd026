"""Every figure of the application: calibration and prediction (the paper's Figs. 6-7), plans, the demo.

matplotlib is imported inside the functions (the Agg backend unless a file backend or a display is
already in use), so importing this module is cheap and never opens a window. Each function takes
``ax=None`` or returns a figure; :func:`finish_figure` titles, lays out, saves and closes one.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wheelloader.estimator import BucketPath, Calibration, CycleLog, Loader, Pile, Prediction
from wheelloader.planner import ParetoPoint


def _pyplot() -> Any:
    import os

    import matplotlib

    has_display = bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if matplotlib.get_backend().lower() not in ("agg", "pdf", "svg", "ps", "cairo") and not has_display:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_pile_and_paths(pile: Pile, paths: Sequence[BucketPath], ax: Any = None, carved: Sequence[Pile] = (),
                        x_range: tuple[float, float] | None = None) -> Any:
    """Pile surface, the soil each cycle removed and each cycle's tip path, in metres, equal aspect.

    ``carved[k]`` is the surface after path ``k``: the soil between it and the surface before is filled
    in path ``k``'s colour, so a path and what it removed read as one; the legend sits outside the axes.
    """
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(7, 4))
    lo, hi = x_range or (pile.x0, min(pile.x_end, max(float(np.max(p.x)) for p in paths) + 0.5) if paths else
                         pile.x_end)
    xs = np.linspace(lo, hi, 800)
    ground = min(0.0, float(pile.heights.min())) - 0.05
    final = carved[-1].surface_height(xs) if carved else pile.surface_height(xs)
    ax.fill_between(xs, final, ground, color="#d9c4a0", lw=0, label="soil left")
    ax.plot(xs, pile.surface_height(xs), color="#5c4424", lw=1.2, ls="--", label="surface before cycle 1")
    top = pile.surface_height(xs)
    for k, surface in enumerate(carved):
        below = surface.surface_height(xs)
        ax.fill_between(xs, below, top, where=below < top - 1e-9, color=f"C{k % 10}", alpha=0.28, lw=0)
        top = below
    for k, path in enumerate(paths):
        label = path.name + (" (path, soil removed)" if k < len(carved) else "")
        ax.plot(path.x, path.z, color=f"C{k % 10}", lw=2.0 if k == len(paths) - 1 else 1.4, label=label)
    ax.plot(xs, final, color="#5c4424", lw=1.2, label="surface after" if carved else None)
    z_top = max([float(np.max(pile.surface_height(xs)))] + [float(np.max(p.z)) for p in paths])
    ax.set_xlim(lo, hi)
    ax.set_ylim(ground - 0.05, z_top + 0.15)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_aspect("equal", adjustable="box")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
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
    if prediction.band is not None:
        ax.fill_between(t, prediction.band.lower_r, prediction.band.upper_r, color="C0", alpha=0.2, lw=0,
                        label=f"{prediction.band.level:.0%} band of F_R")
    ax.plot(t, prediction.resultant, lw=1.8, label="predicted F_R")
    ax.plot(t, prediction.tangential, lw=1, ls="--", label="predicted F_T")
    ax.plot(t, prediction.normal, lw=1, ls=":", label="predicted F_N")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("force [N]")
    if prediction.quality is not None:
        ax.set_title(f"F_R RMSE {prediction.quality.rmse_r:.0f} N ({prediction.quality.percent_r:.1f} %)")
    ax.legend(fontsize=8)
    return finish_figure(fig, out, title)


def plot_cycles_fit(cycles: Sequence[CycleLog], calibration: Calibration, out: str | Path | None = None,
                    title: str | None = None) -> Any:
    """A calibration from several cycles: observed vs fitted F_R of each cycle, one panel per cycle."""
    from wheelloader.estimator import predict

    plt = _pyplot()
    fig, axes = plt.subplots(1, len(cycles), figsize=(4.5 * len(cycles), 3.8), squeeze=False)
    for k, (ax, cycle) in enumerate(zip(axes[0], cycles, strict=True)):
        pred = predict(calibration, cycle)
        ax.plot(cycle.path.t, cycle.resultant, color="0.5", lw=1, label="observed F_R")
        ax.plot(cycle.path.t, pred.resultant, lw=1.6, label="fitted F_R")
        q = pred.quality
        ax.set_title(f"cycle {k}: {cycle.path.name}" + (f" ({q.percent_r:.1f} %)" if q is not None else ""),
                     fontsize=9)
        ax.set_xlabel("t [s]")
        ax.legend(fontsize=7)
    axes[0][0].set_ylabel("F_R [N]")
    return finish_figure(fig, out, title)


def finish_figure(fig: Any, out: str | Path | None = None, title: str | None = None, dpi: int = 120) -> Any:
    """Add the title, lay out, and with ``out`` save the figure there and close it; return the figure."""
    plt = _pyplot()
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if out is not None:
        import matplotlib

        if not (matplotlib.rcParams["figure.autolayout"] or matplotlib.rcParams["figure.constrained_layout.use"]):
            # the layout is done: without the place-holder engine tight_layout leaves, savefig skips a second,
            # undrawn pass over the figure (the same PNG bytes, ~15 % less CPU for the demo's figures)
            fig.set_layout_engine(None)
        fig.savefig(out, dpi=dpi)
        plt.close(fig)
    return fig


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
    # head room above the highest limit or force for the legend, so it hides neither a limit nor a curve
    peak = max(loader.max_push_force, loader.max_lift_force, float(np.max(forces["F_T"])),
               float(np.max(forces["F_N"]))) / 1e3
    ax.set_ylim(min(0.0, ax.get_ylim()[0]), 1.4 * peak)
    ax.legend(loc="upper left", fontsize=8, ncol=2)
    ax.set_title("predicted forces along the plan")

    if pareto:
        _pareto_panel(axes[2], pareto, chosen_weight, baseline_point, plan_point)
    return finish_figure(fig, out, title, dpi=110)


def _pareto_panel(ax: Any, pareto: Sequence[ParetoPoint], chosen_weight: float | None,
                  baseline_point: tuple[float, float] | None, plan_point: tuple[float, float] | None) -> None:
    """The Pareto panel of :func:`plot_plan`: fill against energy of the sweep, the plan and the baseline."""
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
    _label_weights(ax, pareto)
    if bad:
        ax.plot([p.energy / 1e3 for p in bad], [p.fill for p in bad], "x", color="tab:red", ms=8,
                label="failed the NumPy check")
    if plan_point is not None:
        label = "this plan" if chosen_weight is None else f"this plan (λ = {chosen_weight:g}/kJ)"
        ax.plot(plan_point[1] / 1e3, plan_point[0], "s", mfc="none", mec="k", ms=11, label=label)
    if baseline_point is not None:
        ax.plot(baseline_point[1] / 1e3, baseline_point[0], "D", color="tab:gray", label="Bezier baseline")
    ax.set_xlabel("energy [kJ] (NumPy re-simulation)")
    ax.set_ylabel("fill [m³]")
    ax.margins(x=0.12, y=0.15)  # the weight labels stay inside the axes
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("Pareto sweep: fill against energy, labelled by λ [1/kJ]", fontsize=10)


def _label_weights(ax: Any, points: Sequence[ParetoPoint], near: float = 0.04) -> None:
    """Label each sweep point with its energy weight; points closer than ``near`` (a fraction of the data
    range) share one label ("λ = 0.01, 0.05") instead of printing over each other."""
    xy = np.array([[p.energy / 1e3, p.fill] for p in points], dtype=float)
    finite = np.all(np.isfinite(xy), axis=1)
    if not finite.any():
        return
    span = np.ptp(xy[finite], axis=0)
    span[span <= 0.0] = 1.0
    groups: list[list[int]] = []
    for i in np.flatnonzero(finite):
        for group in groups:
            if np.all(np.abs((xy[i] - xy[group[0]]) / span) < near):
                group.append(int(i))
                break
        else:
            groups.append([int(i)])
    for group in groups:
        text = "λ = " + ", ".join(f"{points[i].energy_weight:g}" for i in sorted(group,
                                                                             key=lambda i: points[i].energy_weight))
        x, y = xy[group].mean(axis=0)
        ax.annotate(text, (x, y), fontsize=7, textcoords="offset points", xytext=(0, -13), ha="center",
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})


def new_figure(rows: int = 1, cols: int = 2, size: tuple[float, float] = (11, 4)) -> tuple[Any, Any]:
    """A new figure and axes."""
    plt = _pyplot()
    return plt.subplots(rows, cols, figsize=size)
