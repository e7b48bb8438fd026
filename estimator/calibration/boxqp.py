"""Exact, batched solver of small box-constrained linear least-squares problems.

Solves, for many independent problems at once,

    min_x  x^T H x - 2 g^T x + c     s.t.  lo <= x <= hi,

with ``H`` symmetric positive semi-definite of size ``k <= 5`` (the normal
equations of a bounded linear least-squares fit). The minimiser of a convex
quadratic over a box lies in the relative interior of one face, where it is
the unconstrained minimiser over that face's affine hull; so enumerating the
``3^k`` faces (each variable free, at its lower or at its upper bound),
keeping the feasible face minimisers and taking the best is exact. Every
face is solved for all problems in one vectorised step.
"""

from __future__ import annotations

import itertools

import numpy as np


def solve_box_qp(H: np.ndarray, g: np.ndarray, c: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                 feas_tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Minimise ``x^T H x - 2 g^T x + c`` over ``lo <= x <= hi`` for a batch of problems.

    Parameters
    ----------
    H : numpy.ndarray
        Shape ``(G, k, k)``, symmetric positive semi-definite.
    g : numpy.ndarray
        Shape ``(G, k)``.
    c : numpy.ndarray
        Shape ``(G,)``: the constant (sum of squared data).
    lo, hi : numpy.ndarray
        Shape ``(k,)``: finite bounds, ``lo <= hi``.
    feas_tol : float
        Relative feasibility tolerance on free variables.

    Returns
    -------
    x : numpy.ndarray
        Shape ``(G, k)``: minimisers.
    cost : numpy.ndarray
        Shape ``(G,)``: minimum values (clipped at 0).
    """
    H = np.asarray(H, dtype=float)
    g = np.asarray(g, dtype=float)
    G, k, _ = H.shape
    # Scale to unit diagonal for well-conditioned face solves.
    diag = np.sqrt(np.maximum(np.einsum("gii->gi", H), 1e-300))
    s = 1.0 / diag
    Hs = H * s[:, :, None] * s[:, None, :]
    gs = g * s
    los = lo[None, :] / s
    his = hi[None, :] / s
    ridge = 1e-12 * np.eye(k)
    best = np.full(G, np.inf)
    best_x = np.zeros((G, k))
    span = np.maximum(his - los, 1e-300)
    for free_mask in itertools.product((True, False), repeat=k):
        free = [i for i in range(k) if free_mask[i]]
        fixed = [i for i in range(k) if not free_mask[i]]
        if free:
            inv = np.linalg.inv(Hs[:, free][:, :, free] + ridge[: len(free), : len(free)])
        for choice in itertools.product((0, 1), repeat=len(fixed)):
            x = np.empty((G, k))
            for j, side in zip(fixed, choice, strict=True):
                x[:, j] = los[:, j] if side == 0 else his[:, j]
            if free:
                rhs = gs[:, free]
                if fixed:
                    rhs = rhs - np.einsum("gij,gj->gi", Hs[:, free][:, :, fixed], x[:, fixed])
                xf = np.einsum("gij,gj->gi", inv, rhs)
                x[:, free] = xf
                ok = np.all((xf >= los[:, free] - feas_tol * span[:, free])
                            & (xf <= his[:, free] + feas_tol * span[:, free]), axis=1)
                x[:, free] = np.clip(xf, los[:, free], his[:, free])
            else:
                ok = np.ones(G, dtype=bool)
            val = np.einsum("gi,gij,gj->g", x, Hs, x) - 2.0 * np.einsum("gi,gi->g", gs, x)
            better = ok & (val < best)
            best = np.where(better, val, best)
            best_x = np.where(better[:, None], x, best_x)
    return best_x * s, np.maximum(best + c, 0.0)
