"""Drawing of the bucket-loading env (matplotlib, imported only when rendering).

The frame shows the configured pile (dotted), the start-of-cycle surface
(dashed), the carved surface (filled), the bucket with its fill and arrows of
the measured soil forces on the blade (F_T along the blade, F_N across it).
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


class EnvRenderer:
    """Renders env states to RGB arrays (``"rgb_array"``) or to a window (``"human"``)."""

    def __init__(self, mode: str, cfg: Any, size: tuple[float, float] = (6.4, 3.6), dpi: int = 100) -> None:
        import matplotlib

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
        del matplotlib
        self.ax = self.fig.add_axes((0.1, 0.12, 0.88, 0.8))

    def draw(self, state: dict[str, Any]) -> np.ndarray | None:
        """Draw ``state`` (see BucketLoadingEnv.render_state); return the RGB frame (H, W, 3) uint8."""
        ax = self.ax
        ax.clear()
        pile0, start, carved = state["pile"], state["start_pile"], state["carved"]
        xs = carved.x
        ax.fill_between(xs, carved.heights.min() - 0.05, carved.heights, color="#c8a165", lw=0)
        ax.plot(xs, start.heights, "--", color="#6b4f2a", lw=1.0, label="start of cycle")
        ax.plot(pile0.x, pile0.heights, ":", color="0.4", lw=0.8, label="initial pile")
        x, z, th = state["x"], state["z"], state["blade_angle"]
        et = np.array([math.cos(th), math.sin(th)])
        en = np.array([-math.sin(th), math.cos(th)])
        tip = np.array([x, z])
        back = tip - state["floor_length"] * et
        top = back + BACK_HEIGHT * en
        frac = min(max(state["fill"] / state["capacity"], 0.0), 1.0)
        if frac > 0.0:
            hf = BACK_HEIGHT * frac
            soil = np.array([tip, back, back + hf * en, tip + 0.3 * hf * en])
            ax.fill(soil[:, 0], soil[:, 1], color="#8c6a3c", lw=0)
        outline = np.array([top, back, tip])
        ax.plot(outline[:, 0], outline[:, 1], color="0.15", lw=2.5)
        scale = ARROW_SCALE
        f_t, f_n = state["F_T"], state["F_N"]
        for vec, mag, color, label in ((-et, f_t, "tab:red", "F_T"), (-en, f_n, "tab:blue", "F_N")):
            if abs(mag) > 1.0:
                d = vec * mag * scale
                ax.annotate("", xy=tip + d, xytext=tip,
                            arrowprops={"arrowstyle": "->", "color": color, "lw": 2})
                ax.text(*(tip + d), f"{label} {mag / 1000:.1f} kN", color=color, fontsize=8)
        ax.set_title(f"t = {state['time']:.2f} s   fill {100 * frac:.0f} %", fontsize=9)
        x_lo, x_hi = pile0.x0, min(pile0.x_end, pile0.x0 + 4.5)
        ax.set_xlim(x_lo, x_hi)
        z_lo = float(pile0.heights.min()) - 0.45
        ax.set_ylim(z_lo, z_lo + (x_hi - x_lo) * 0.5)
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]", fontsize=8)
        ax.set_ylabel("z [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(loc="upper left", fontsize=7, frameon=False)
        self.fig.canvas.draw()
        if self.mode == "human" and self._plt is None:
            return None
        frame = np.asarray(self.fig.canvas.buffer_rgba())[..., :3].copy()
        if self._plt is not None:
            self._plt.pause(1.0 / max(self.cfg.control_rate, 1.0))
        return None if self.mode == "human" else frame

    def close(self) -> None:
        """Release the figure."""
        if self._plt is not None:
            self._plt.close(self.fig)
        self.fig = None


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
