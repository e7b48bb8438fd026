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
        self._base = np.arange(n) * m  # flat index of each row's first node
        self._base_f = self._base.astype(float)  # the same, as floats (exact: far below 2**53)
        # the start surface most rows share (the configured pile): rows on it are gathered from this one row,
        # which stays in the cache, instead of from their own rows of the n x m array (the same values)
        self._shared = np.array(pile.heights, dtype=float)
        self._shared_from = pile.heights  # the array it was copied from (an identity check first)
        self._own = np.ones(n, dtype=bool)  # rows whose start surface is not the shared one (or not set yet)
        self._n_own = n
        # Nodes each row's carve may have changed since its start, [_lo, _hi] (the whole row where its start is
        # not the shared one): elsewhere its carved surface is the shared one, read from that cached row instead
        # of the n x m array (the same values, far fewer cache misses)
        self._lo = np.full(n, -np.inf)
        self._hi = np.full(n, np.inf)

    def set(self, i: int, heights: np.ndarray) -> None:
        """Start row ``i`` afresh on ``heights`` (start and carved surface)."""
        self.start[i] = heights
        self.carved[i] = heights
        own = not (heights is self._shared_from or np.array_equal(heights, self._shared))
        self._n_own += int(own) - int(self._own[i])
        self._own[i] = own
        self._lo[i], self._hi[i] = (-np.inf, np.inf) if own else (np.inf, -np.inf)

    def pile(self, i: int, carved: bool = True) -> Pile:
        """Row ``i``'s carved (or start-of-cycle) surface as a :class:`Pile` (a copy)."""
        return self.as_pile((self.carved if carved else self.start)[i])

    def as_pile(self, heights: np.ndarray) -> Pile:
        """``heights`` on this grid as a :class:`Pile` (a copy)."""
        return Pile(self.x0, self.spacing, heights.copy())

    def _bases(self, rows: np.ndarray | None, two_d: bool) -> np.ndarray:
        if rows is None:
            return self._base[:, None] if two_d else self._base
        base = rows * self.nodes
        return base[:, None] if two_d else base

    def _interpolate(self, flat: np.ndarray, base: np.ndarray | float, x: np.ndarray) -> np.ndarray:
        """Height of the polyline rows of ``flat`` at ``x`` (a fresh array of x's shape; ``base``: the flat index of
        each point's row start, broadcast against ``x`` along its last axis) [m]; Pile.height_at's arithmetic
        (za + f * (zb - za) with f = u - floor(u), u clipped to the grid)."""
        last = self.nodes - 1
        u = np.subtract(x, self.x0)
        u /= self.spacing
        np.clip(u, 0.0, last, out=u)
        node = np.floor(u)  # = int(u) for u >= 0
        f = np.subtract(u, node, out=u)
        node += base
        idx = node.astype(np.int64)
        za = flat.take(idx)
        # the next node: at u = last (f = 0) that is the next row's first node, or clipped to the array's end; its
        # finite height h gives za + 0 * (h - za) = za, the value at the last node, as Pile.height_at gives
        idx += 1
        dz = flat.take(idx, mode="clip")
        dz -= za
        dz *= f
        dz += za
        return dz

    def carved_height(self, x: np.ndarray) -> np.ndarray:
        """Carved surface height of every row at ``x`` of shape ``(k, n)`` (``k`` points per row), as
        ``height(carved, None, x)``: nodes outside a row's carved range come from the shared start surface [m]."""
        if self._n_own:
            return self.height(self.carved, None, x)
        last = self.nodes - 1
        u = np.subtract(x, self.x0)
        u /= self.spacing
        np.clip(u, 0.0, last, out=u)
        node = np.floor(u)
        f = np.subtract(u, node, out=u)
        idx = node.astype(np.int64)
        za = self._shared.take(idx)
        zb = self._shared.take(idx + 1, mode="clip")
        # carved nodes: i or i + 1 in [lo, hi]
        need = np.greater_equal(node, self._lo - 1.0)
        need &= node <= self._hi
        if need.any():
            at = np.flatnonzero(need)
            where = idx.reshape(-1).take(at)
            where += (at % idx.shape[-1]) * self.nodes  # the flat index in the row of the point's sub-env
            flat = self.carved.reshape(-1)
            za.reshape(-1)[at] = flat.take(where)
            where += 1
            zb.reshape(-1)[at] = flat.take(where, mode="clip")
        zb -= za
        zb *= f
        zb += za
        return zb  # za + f * (zb - za)

    def height(self, heights: np.ndarray, rows: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        """Surface height of ``heights[rows]`` (every row for None) at ``x`` (as Pile.height_at, row-wise): ``x`` of
        shape ``(len(rows),)``, or ``(k, len(rows))`` for ``k`` points per row [m]."""
        base = self._base_f if rows is None else (rows * self.nodes).astype(float)
        return self._interpolate(heights.reshape(-1), base, x)

    def contact(self, rows: np.ndarray | None, x: np.ndarray, z: np.ndarray, th: np.ndarray, slope_window: float,
                floor_length: float):
        """(depth, rho, alpha, blade length in soil, surface height) against the start surfaces of ``rows``
        (every row for None; as contact_single)."""
        w = slope_window
        pts = np.empty((3, x.size))
        np.add(x, w, out=pts[0])
        np.subtract(x, w, out=pts[1])
        pts[2] = x
        own = self._own if rows is None else self._own[rows]
        if self._n_own == 0 or not own.any():  # every row on the shared start surface
            h = self._interpolate(self._shared, 0.0, pts)
        else:
            h = self.height(self.start, rows, pts)
        alpha = h[0] - h[1]
        alpha /= 2.0 * w
        alpha = np.arctan(alpha, out=alpha)
        surface = h[2]
        vertical = surface - z
        depth = np.maximum(vertical, 0.0, out=vertical)
        depth *= np.cos(alpha)
        rho = alpha - th
        return depth, rho, alpha, blade_length_in_soil(depth, rho, floor_length), surface

    def carve(self, rows: np.ndarray | None, xa: np.ndarray, za: np.ndarray, xb: np.ndarray, zb: np.ndarray):
        """Cut the segments (xa, za)-(xb, zb) into the carved surfaces of ``rows`` (every row for None; batched
        SurfaceCarver.cut_segment).

        Returns
        -------
        (flat indices, old heights, removed area)
            The changed nodes (for :meth:`undo`) and the area removed per row [m^2] (None when nothing
            was cut).
        """
        x0, sp, m = self.x0, self.spacing, self.nodes
        # the segment's first and last node (as floats: exact integers, so the same as the int64 indices)
        lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
        lo -= x0
        lo /= sp
        lo -= 1e-12
        i0 = np.ceil(lo, out=lo)
        np.maximum(i0, 0.0, out=i0)
        hi -= x0
        hi /= sp
        hi += 1e-12
        i1 = np.floor(hi, out=hi)
        np.minimum(i1, m - 1, out=i1)
        width_k = int((i1 - i0).max()) + 1 if i0.size else 0
        empty = (np.zeros(0, np.int64), np.zeros(0), None)
        if width_k <= 0:
            return empty
        # (node k of the segment, row): the rows are contiguous, and summing over k goes in node order
        cols = np.add.outer(np.arange(width_k, dtype=float), i0)
        valid = cols <= i1
        cols_c = np.minimum(cols, m - 1, out=cols)
        xi = cols_c * sp
        xi += x0  # x0 + col * sp
        dx = xb - xa
        flat = dx == 0.0
        safe = np.where(flat, 1.0, dx)
        xi -= xa
        xi *= zb - za
        xi /= safe
        zc = np.add(za, xi, out=xi)  # za + (zb - za) * (xi - xa) / dx
        if flat.any():
            zc = np.where(flat, np.minimum(za, zb), zc)
        flat_h = self.carved.reshape(-1)
        node = cols_c.astype(np.int64)
        flat_idx = node + self._bases(rows, False)
        if rows is None and not self._n_own:  # the row's own nodes only where its carve may have changed them
            old = self._shared.take(node)
            need = np.greater_equal(cols_c, self._lo)
            need &= cols_c <= self._hi
            if need.any():
                at = np.flatnonzero(need)
                old.reshape(-1)[at] = flat_h.take(flat_idx.reshape(-1).take(at))
        else:
            old = flat_h.take(flat_idx)
        cut = zc < old
        cut &= valid
        if not cut.any():
            return empty
        hit = cut.any(axis=0)  # rows that cut: their carved range grows by the segment's nodes
        if rows is None:
            np.minimum(self._lo, i0, out=self._lo, where=hit)
            np.maximum(self._hi, i1, out=self._hi, where=hit)
        else:
            self._lo[rows[hit]] = np.minimum(self._lo[rows[hit]], i0[hit])
            self._hi[rows[hit]] = np.maximum(self._hi[rows[hit]], i1[hit])
        contrib = np.zeros(cut.shape)
        np.subtract(old, zc, out=contrib, where=cut)
        if i0.min() > 0.0 and i1.max() < m - 1:  # no end node (half weight) in any segment
            contrib *= sp
        else:
            contrib *= self._w.take(node)
        area = np.add.reduce(contrib, axis=0)  # over k in node order, as SurfaceCarver sums
        at = np.flatnonzero(cut)
        idx_u, old_u = flat_idx.take(at), old.take(at)
        flat_h[idx_u] = zc.take(at)
        return idx_u, old_u, area

    def undo(self, idx_u: np.ndarray, old_u: np.ndarray, rows: np.ndarray) -> None:
        """Restore the nodes of ``rows`` that :meth:`carve` changed (flat indices and old heights)."""
        back = np.isin(idx_u // self.nodes, rows)
        self.carved.reshape(-1)[idx_u[back]] = old_u[back]
