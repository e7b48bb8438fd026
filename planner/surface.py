"""A smooth stand-in for the pile surface, for the CasADi planner.

The estimator's :class:`~wheelloader.estimator.Pile` is piecewise linear on a
2 mm grid; a carved pile has kinks and near-vertical walls. IPOPT needs
twice-differentiable expressions, so the planner sees the surface as the
polyline through its heights at knots ``x_i = x0 + i * spacing`` (5 cm apart
by default) with every kink rounded by a softplus over ``kappa`` (1 cm); see
:meth:`SurfaceGrid.height`. Plain SX arithmetic: no look-up tables, whose
parametric B-spline fits made each IPOPT iteration seconds long. The knot
heights and ``x0`` are NLP *parameters*, so one solver serves every pile.
The local slope follows the estimator's definition, the chord slope
over ``x +- slope_window`` (:mod:`wheelloader.estimator.kinematics`).
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from wheelloader.estimator import DEFAULT_SLOPE_WINDOW, Pile
from wheelloader.estimator.checks import check_int, check_range
from wheelloader.estimator.errors import PlanningError


@dataclass(frozen=True)
class SurfaceGrid:
    """Layout of the smooth surface: knot count, spacing and rounding width.

    Parameters
    ----------
    knots : int
        Number of knots (default 72).
    spacing : float
        Knot spacing [m] (default 0.05 m: 3.55 m of surface).
    kappa : float
        Width over which each kink of the knot polyline is rounded [m] (default 0.01 m).
    behind : float
        How far behind the path's start the first knot lies [m] (default 0.3 m).
    window : int
        Knots per node window (default 20: 0.95 m). Each node of the NLP sees
        the surface through the knots of a window placed around the node's
        position in the initial guess (:meth:`window_parameters`), the
        polyline's earlier knots folded into one straight line: the same
        heights as through all knots while the node stays inside its window,
        at a quarter of the cost per evaluation.
    """

    knots: int = 72
    spacing: float = 0.05
    kappa: float = 0.01
    behind: float = 0.3
    window: int = 20

    def __post_init__(self) -> None:
        check_int("SurfaceGrid.knots", self.knots, minimum=4, error=PlanningError)
        for name in ("spacing", "kappa"):
            check_range(f"SurfaceGrid.{name}", getattr(self, name), 0.0, None, low_open=True, error=PlanningError)
        check_range("SurfaceGrid.behind", self.behind, 0.0, None, error=PlanningError)
        check_int("SurfaceGrid.window", self.window, minimum=4, maximum=self.knots - 2, error=PlanningError)

    @property
    def size(self) -> int:
        """Number of NLP parameters the surface takes: ``x0`` and one height per knot."""
        return 1 + self.knots

    @property
    def length(self) -> float:
        """Span of the knots [m]."""
        return self.spacing * (self.knots - 1)

    def parameters(self, pile: Pile, x_start: float) -> np.ndarray:
        """Surface parameters ``[x0, z_0, ..., z_{K-1}]`` sampling ``pile`` from ``x_start - behind``."""
        if not isinstance(pile, Pile):
            raise PlanningError(f"pile must be a Pile, got {type(pile).__name__}")
        x0 = float(x_start) - self.behind
        xs = x0 + self.spacing * np.arange(self.knots)
        return np.concatenate([[x0], np.asarray(pile.surface_height(xs), dtype=float)])

    def height(self, x, params):
        """Smooth surface height at ``x`` [m] from :meth:`parameters` (CasADi symbols or NumPy values).

        The piecewise-linear interpolant of the knot heights with each kink rounded by a softplus of
        width ``kappa``: ``z(x) = z_0 + s_0 (x - x_0) + sum_i (s_i - s_{i-1}) kappa softplus((x - x_i) / kappa)``.
        """
        x0, z = params[0], params[1:]
        k, dx = self.kappa, self.spacing
        symbolic = isinstance(x, (ca.SX, ca.MX)) or isinstance(params, (ca.SX, ca.MX))
        softplus = _softplus_casadi if symbolic else _softplus_numpy
        slope_prev = (z[1] - z[0]) / dx
        out = z[0] + slope_prev * (x - x0)
        for i in range(1, self.knots - 1):
            slope = (z[i + 1] - z[i]) / dx
            out = out + (slope - slope_prev) * k * softplus((x - x0 - i * dx) / k)
            slope_prev = slope
        return out

    @property
    def window_size(self) -> int:
        """Number of NLP parameters of one node window: ``x_a, z_a, s_a`` and one slope change per knot."""
        return 3 + self.window

    def window_parameters(self, params: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """Windows of the surface ``params`` (from :meth:`parameters`) around each of ``centres`` [m].

        Returns an array ``(len(centres), window_size)``: per centre the first
        window knot ``x_a``, its height ``z_a``, the slope ``s_a`` of the
        segment before it, and the slope changes at the window's knots. See
        :meth:`window_height`.
        """
        x0, z = float(params[0]), np.asarray(params[1:], dtype=float)
        dx, m = self.spacing, self.window
        slopes = np.diff(z) / dx  # segment i: knots i -> i + 1
        first = np.rint((np.asarray(centres, dtype=float) - x0) / dx).astype(int) - m // 2
        first = np.clip(first, 1, self.knots - 1 - m)
        j = first[:, None] + np.arange(m)[None, :]
        out = np.empty((first.size, self.window_size))
        out[:, 0] = x0 + dx * first
        out[:, 1] = z[first]
        out[:, 2] = slopes[first - 1]
        out[:, 3:] = slopes[j] - slopes[j - 1]
        return out

    def window_range(self, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` [m]: where each window reproduces the full surface (one knot spacing beyond its ends)."""
        lo = windows[:, 0] - self.spacing
        return lo, windows[:, 0] + self.spacing * self.window

    def window_height(self, x, wp):
        """Smooth surface height at ``x`` [m] through one window ``wp`` (CasADi symbols or NumPy values).

        ``z(x) = z_a + s_a (x - x_a) + sum_j d_j kappa softplus((x - x_a - j spacing) / kappa)``: inside the
        window's range the same as :meth:`height` with all knots (up to the softplus tails of the knots
        before it, below ``kappa exp(-spacing / kappa)``).
        """
        k, dx = self.kappa, self.spacing
        symbolic = isinstance(x, (ca.SX, ca.MX)) or isinstance(wp, (ca.SX, ca.MX))
        softplus = _softplus_casadi if symbolic else _softplus_numpy
        xa = wp[0]
        out = wp[1] + wp[2] * (x - xa)
        for j in range(self.window):
            out = out + wp[3 + j] * k * softplus((x - xa - j * dx) / k)
        return out

    def window_slope_angle(self, x, wp, window: float = DEFAULT_SLOPE_WINDOW):
        """Chord slope angle over ``x +- window`` [rad] through one node window."""
        rise = self.window_height(x + window, wp) - self.window_height(x - window, wp)
        if isinstance(rise, (ca.SX, ca.MX)):
            return ca.atan(rise / (2.0 * window))
        return np.arctan(rise / (2.0 * window))

    def slope_angle(self, x, params, window: float = DEFAULT_SLOPE_WINDOW):
        """Chord slope angle over ``x +- window`` [rad], as :meth:`Pile.slope_angle`."""
        rise = self.height(x + window, params) - self.height(x - window, params)
        if isinstance(rise, (ca.SX, ca.MX)):
            return ca.atan(rise / (2.0 * window))
        return np.arctan(rise / (2.0 * window))


def _softplus_casadi(y):
    return ca.fmax(y, 0.0) + ca.log1p(ca.exp(-ca.fabs(y)))


def _softplus_numpy(y):
    y = np.asarray(y, dtype=float)
    return np.maximum(y, 0.0) + np.log1p(np.exp(-np.abs(y)))
