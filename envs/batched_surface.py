"""Pile surfaces of many sub-envs on one grid, as rows of 2-D arrays (the batched env's geometry).

Row ``i`` holds sub-env ``i``'s start-of-cycle surface (depth is measured to
it) and its carved surface. The operations reproduce the single env's
:meth:`Pile.height_at`, :func:`~wheelloader.estimator.contact_single` and
:meth:`SurfaceCarver.cut_segment` row-wise, in the same floating-point order.
"""

from __future__ import annotations

import numpy as np

from wheelloader.estimator import Pile, blade_length_in_soil

__all__ = ["BatchedSurfaces"]


class BatchedSurfaces:
    """Start-of-cycle and carved surfaces of ``n`` sub-envs on the grid of ``pile``.

    Parameters
    ----------
    pile : Pile
        Gives the grid (``x0``, ``spacing``, node count).
    n : int
        Number of rows (sub-envs).
    """

    def __init__(self, pile: Pile, n: int) -> None:
        self.x0, self.spacing = pile.x0, pile.spacing
        self.nodes = m = pile.heights.size
        self.start = np.empty((n, m))  # start-of-cycle surfaces (depth)
        self.carved = np.empty((n, m))  # carved surfaces
        self._w = np.full(m, self.spacing)  # trapezoid weights of the nodes
        self._w[0] = self._w[-1] = 0.5 * self.spacing

    def set(self, i: int, heights: np.ndarray) -> None:
        """Start row ``i`` afresh on ``heights`` (start and carved surface)."""
        self.start[i] = heights
        self.carved[i] = heights

    def pile(self, i: int, carved: bool = True) -> Pile:
        """Row ``i``'s carved (or start-of-cycle) surface as a :class:`Pile` (a copy)."""
        return self.as_pile((self.carved if carved else self.start)[i])

    def as_pile(self, heights: np.ndarray) -> Pile:
        """``heights`` on this grid as a :class:`Pile` (a copy)."""
        return Pile(self.x0, self.spacing, heights.copy())

    def height(self, heights: np.ndarray, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Surface height of ``heights[rows]`` at ``x`` (as Pile.height_at, row-wise; x may be 2-D) [m]."""
        m = self.nodes
        last = m - 1
        u = np.clip((x - self.x0) / self.spacing, 0.0, last)
        i = u.astype(np.int64)
        f = u - i
        base = rows * m if x.ndim == 1 else (rows * m)[:, None]
        flat = heights.reshape(-1)
        za = flat[base + i]
        return za + f * (flat[base + np.minimum(i + 1, last)] - za)

    def contact(self, rows: np.ndarray, x: np.ndarray, z: np.ndarray, th: np.ndarray, slope_window: float,
                floor_length: float):
        """(depth, rho, alpha, blade length in soil, surface height) against the start surfaces of ``rows``
        (as contact_single)."""
        w = slope_window
        h = self.height(self.start, rows, np.stack([x + w, x - w, x], axis=1))
        alpha = np.arctan((h[:, 0] - h[:, 1]) / (2.0 * w))
        vertical = h[:, 2] - z
        depth = np.maximum(vertical, 0.0) * np.cos(alpha)
        rho = alpha - th
        return depth, rho, alpha, blade_length_in_soil(depth, rho, floor_length), h[:, 2]

    def carve(self, rows: np.ndarray, xa: np.ndarray, za: np.ndarray, xb: np.ndarray, zb: np.ndarray):
        """Cut the segments (xa, za)-(xb, zb) into the carved surfaces of ``rows`` (batched
        SurfaceCarver.cut_segment).

        Returns
        -------
        (flat indices, old heights, removed area)
            The changed nodes (for :meth:`undo`) and the area removed per row [m^2] (None when nothing
            was cut).
        """
        x0, sp, m = self.x0, self.spacing, self.nodes
        lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
        i0 = np.maximum(0, np.ceil((lo - x0) / sp - 1e-12).astype(np.int64))
        i1 = np.minimum(m - 1, np.floor((hi - x0) / sp + 1e-12).astype(np.int64))
        count = i1 - i0 + 1
        width_k = int(count.max()) if count.size else 0
        empty = (np.zeros(0, np.int64), np.zeros(0), None)
        if width_k <= 0:
            return empty
        cols = i0[:, None] + np.arange(width_k)
        valid = cols <= i1[:, None]
        cols_c = np.minimum(cols, m - 1)
        xi = x0 + cols_c * sp
        dx = xb - xa
        flat = dx == 0.0
        safe = np.where(flat, 1.0, dx)
        zc = za[:, None] + (zb - za)[:, None] * (xi - xa[:, None]) / safe[:, None]
        zc = np.where(flat[:, None], np.minimum(za, zb)[:, None], zc)
        flat_h = self.carved.reshape(-1)
        flat_idx = (rows * m)[:, None] + cols_c
        old = flat_h[flat_idx]
        cut = valid & (zc < old)
        if not cut.any():
            return empty
        contrib = np.where(cut, self._w[cols_c] * (old - zc), 0.0)
        area = contrib[:, 0].copy()
        for k in range(1, width_k):  # node order, as SurfaceCarver sums
            area += contrib[:, k]
        idx_u, old_u = flat_idx[cut], old[cut]
        flat_h[idx_u] = zc[cut]
        return idx_u, old_u, area

    def undo(self, idx_u: np.ndarray, old_u: np.ndarray, rows: np.ndarray) -> None:
        """Restore the nodes of ``rows`` that :meth:`carve` changed (flat indices and old heights)."""
        back = np.isin(idx_u // self.nodes, rows)
        self.carved.reshape(-1)[idx_u[back]] = old_u[back]
