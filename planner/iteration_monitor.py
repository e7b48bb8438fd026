"""IPOPT's iteration callback as a CasADi :class:`~casadi.Callback`: the planner's NLP solvers
(:mod:`wheelloader.planner.nlp`) hand each iterate to a caller that may stop the solve."""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["IterationMonitor"]


class IterationMonitor(ca.Callback):
    """IPOPT's iteration callback: hands every iterate to :attr:`watch` (a function of the decision vector
    returning True to stop the solve, or None: run on).

    A stop is IPOPT's ``User_Requested_Stop`` at that iterate; it depends on the iterates only, so a solve
    watched this way is as deterministic as one that is not.
    """

    def __init__(self, nx: int, ng: int) -> None:
        ca.Callback.__init__(self)
        self.nx, self.ng = nx, ng
        self.watch = None
        self.construct("iteration_monitor", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "stop"

    def get_sparsity_in(self, i):
        name = ca.nlpsol_out(i)
        if name == "f":
            return ca.Sparsity.scalar()
        if name in ("x", "lam_x"):
            return ca.Sparsity.dense(self.nx)
        if name in ("g", "lam_g"):
            return ca.Sparsity.dense(self.ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        if self.watch is None:
            return [0]
        return [1 if self.watch(np.array(arg[0]).ravel()) else 0]
