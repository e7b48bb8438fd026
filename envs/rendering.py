"""Drawing of the bucket-loading env (matplotlib, imported only when rendering).

The frame shows the configured pile (dotted), the start-of-cycle surface
(dashed), the carved surface (filled), the bucket with its fill and arrows of
the measured soil forces on the blade (F_T along the blade, F_N across it), their
values in the arrows' colours in the upper right corner.

The figure is built once per pile: axes, ticks, labels, legend and the configured pile are drawn into a
background that is kept; each frame restores it and redraws only the artists that move (their data are
updated in place), which is what makes ``rgb_array`` rendering fast (``benchmarks/render_speed.py``).
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

#: Force arrow scale [m per N].
ARROW_SCALE = 1.0 / 40_000.0
#: Height of the drawn bucket back wall [m].
BACK_HEIGHT = 0.45
#: Forces below this are not drawn as arrows [N].
MIN_ARROW_FORCE = 1.0
_SOIL = "#c8a165"
_FORCE_COLORS = {"F_T": "tab:red", "F_N": "tab:blue"}


class EnvRenderer:
    """Renders env states to RGB arrays (``"rgb_array"``) or to a window (``"human"``).

    Parameters
    ----------
    mode : str
        ``"rgb_array"`` or ``"human"``.
    cfg : EnvConfig
        The env's settings (its control rate paces ``"human"`` rendering).
    size : (float, float)
        Figure size [in]; with ``dpi`` the frame size (default 640 x 360 pixels).
    dpi : int
        Dots per inch.
    """

    def __init__(self, mode: str, cfg: Any, size: tuple[float, float] = (6.4, 3.6), dpi: int = 100) -> None:
        self.mode = mode
        self.cfg = cfg
        # Without a display, "human" draws off-screen (no window, nothing returned).
        if mode == "human" and _has_display():
            import matplotlib.pyplot as plt

            plt.ion()
            self.fig = plt.figure(figsize=size, dpi=dpi)
            self._plt = plt
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            self.fig = Figure(figsize=size, dpi=dpi)
            FigureCanvasAgg(self.fig)
            self._plt = None
        self.ax = self.fig.add_axes((0.1, 0.12, 0.88, 0.8))
        self._scene_key: tuple | None = None
        self._background: Any = None
        self._artists: dict[str, Any] = {}

    # ------------------------------------------------------------------ scene (once per pile)
    def _build_scene(self, pile0: Any) -> None:
        """Axes, the configured pile and every moving artist (empty); then the kept background."""
        from matplotlib.lines import Line2D
        from matplotlib.patches import FancyArrowPatch, Polygon

        ax = self.ax
        ax.clear()
        x_lo, x_hi = pile0.x0, min(pile0.x_end, pile0.x0 + 4.5)
        z_lo = float(pile0.heights.min()) - 0.45
        ax.set_xlim(x_lo, x_hi)
        ax.set_ylim(z_lo, z_lo + (x_hi - x_lo) * 0.5)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]", fontsize=8)
        ax.set_ylabel("z [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.plot(pile0.x, pile0.heights, ":", color="0.4", lw=0.8, label="initial pile")
        art = {
            "carved": Polygon(np.zeros((3, 2)), closed=True, color=_SOIL, lw=0, zorder=1),
            "start": Line2D([], [], ls="--", color="#6b4f2a", lw=1.0, zorder=2, label="start of cycle"),
            "load": Polygon(np.zeros((4, 2)), closed=True, color="#8c6a3c", lw=0, zorder=3),
            "bucket": Line2D([], [], color="0.15", lw=2.5, zorder=4, solid_capstyle="round"),
            "title": ax.text(0.5, 1.02, "", transform=ax.transAxes, ha="center", va="bottom", fontsize=9),
        }
        for name, color in _FORCE_COLORS.items():
            art[name] = FancyArrowPatch((0, 0), (0, 0), arrowstyle="->", mutation_scale=12, color=color, lw=2,
                                        zorder=5)
        # the values in a fixed corner, in the arrows' colours: never over the bucket or each other
        for row, name in enumerate(_FORCE_COLORS):
            art[name + " value"] = ax.text(0.985, 0.96 - 0.09 * row, "", transform=ax.transAxes, ha="right",
                                           va="top", fontsize=8, color=_FORCE_COLORS[name])
        ax.add_patch(art["carved"])
        ax.add_patch(art["load"])
        ax.add_patch(art["F_T"])
        ax.add_patch(art["F_N"])
        ax.add_line(art["start"])
        ax.add_line(art["bucket"])
        ax.legend(handles=[art["start"], ax.lines[0]], loc="upper left", fontsize=7, frameon=False)
        for artist in art.values():
            artist.set_animated(True)
        self._artists = art
        self.fig.canvas.draw()
        self._background = self.fig.canvas.copy_from_bbox(self.fig.bbox)

    # ------------------------------------------------------------------ frame
    def draw(self, state: dict[str, Any]) -> np.ndarray | None:
        """Draw ``state`` (see BucketLoadingEnv.render_state); return the RGB frame (H, W, 3) uint8."""
        pile0 = state["pile"]
        key = (pile0.x0, pile0.x_end, pile0.heights.tobytes())
        if key != self._scene_key:
            self._build_scene(pile0)
            self._scene_key = key
        self._update(state)
        canvas = self.fig.canvas
        canvas.restore_region(self._background)
        for artist in self._artists.values():
            if artist.get_visible():
                self.ax.draw_artist(artist)
        if self._plt is not None:  # a window: show it
            canvas.blit(self.fig.bbox)
            canvas.flush_events()
            self._plt.pause(1.0 / max(self.cfg.control_rate, 1.0))
        if self.mode == "human":
            return None
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def _update(self, state: dict[str, Any]) -> None:
        art = self._artists
        start, carved = state["start_pile"], state["carved"]
        ylim = self.ax.get_ylim()
        xs, hs = carved.x, carved.heights
        bottom = min(float(hs.min()) - 0.05, ylim[0])
        art["carved"].set_xy(np.concatenate([np.column_stack([xs, hs]), [[xs[-1], bottom], [xs[0], bottom]]]))
        art["start"].set_data(start.x, start.heights)
        x, z, th = state["x"], state["z"], state["blade_angle"]
        et = np.array([math.cos(th), math.sin(th)])
        en = np.array([-math.sin(th), math.cos(th)])
        tip = np.array([x, z])
        back = tip - state["floor_length"] * et
        top = back + BACK_HEIGHT * en
        frac = min(max(state["fill"] / state["capacity"], 0.0), 1.0)
        hf = BACK_HEIGHT * frac
        art["load"].set_visible(frac > 0.0)
        art["load"].set_xy(np.array([tip, back, back + hf * en, tip + 0.3 * hf * en]))
        outline = np.array([top, back, tip])
        art["bucket"].set_data(outline[:, 0], outline[:, 1])
        for name, direction, what in (("F_T", -et, "along the blade"), ("F_N", -en, "across the blade")):
            mag = float(state[name])
            shown = abs(mag) > MIN_ARROW_FORCE
            art[name].set_visible(shown)
            if shown:
                art[name].set_positions(tuple(tip), tuple(tip + direction * mag * ARROW_SCALE))
            art[name + " value"].set_text(f"{name} ({what}) {mag / 1000:.1f} kN")
        art["title"].set_text(f"t = {state['time']:.2f} s   fill {100 * frac:.0f} %")

    def close(self) -> None:
        """Release the figure."""
        if self._plt is not None:
            self._plt.close(self.fig)
        self.fig = None
        self._background = None


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
