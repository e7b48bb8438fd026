"""IPOPT's iteration callback as a CasADi :class:`~casadi.Callback`: the planner's NLP solvers
(:mod:`wheelloader.planner.nlp`) hand each iterate to a caller that may stop the solve."""

from __future__ import annotations

import casadi as ca
import numpy as np

from . import lanes

__all__ = ["IterationMonitor"]


class IterationMonitor(ca.Callback):
    """IPOPT's iteration callback: hands every iterate to :attr:`watch` (a function of the decision vector
    returning True to stop the solve, or None: run on).

    A stop is IPOPT's ``User_Requested_Stop`` at that iterate; it depends on the iterates only, so a solve
    watched this way is as deterministic as one that is not.

    A solve in a cancelled lane (:mod:`.lanes`) stops at its next iterate.

    A Ctrl-C that arrives while this callback runs in Python is turned into a stop request instead of an
    exception: CasADi would print the exception's traceback and carry on. The SIGINT handler that
    :func:`wheelloader.planner.interrupt.guarded` installs has recorded it already and re-raises
    ``KeyboardInterrupt`` once the solve returns.
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
        try:
            if lanes.cancelled():  # the lane's cancel event (planner.lanes): stop at this iterate
                return [1]
            if self.watch is None:
                return [0]
            return [1 if self.watch(np.array(arg[0]).ravel()) else 0]
        except (KeyboardInterrupt, SystemError) as error:
            if isinstance(error, KeyboardInterrupt) or isinstance(error.__cause__, KeyboardInterrupt):
                return [1]  # Ctrl-C inside the callback (raw, or wrapped by SWIG): stop the solve now
            raise
