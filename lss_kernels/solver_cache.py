"""A solver kept for the next pair of the same size: :class:`SolverCache`.

A new :class:`~lss_kernels.Solver` loads its kernels again, which takes seconds; a solver of
the same image size, search range and parameters is :meth:`~lss_kernels.Solver.reset`
instead.  The cache also keeps a set-up made only to locate a start (a whole photo's point,
:mod:`lss_kernels.photo`) for the solve that follows it on the same crop.
"""
from __future__ import annotations

import numpy as np

from .params import c_max

__all__ = ["SolverCache"]


class SolverCache:
    """Keeps the last solver for the next pair of the same image size, search range and
    parameters, and closes it when another one is needed."""

    def __init__(self):
        self.key, self.solver = None, None
        self.primed = None    # (pair, start, left) set up by locate() and not yet run

    def solve_pair(self, left, right, d_max, init, init_frame, params, callback=None,
                   anchor=None):
        """Solve a pair (solved again when the model collapses,
        :func:`~lss_kernels.checks.recovery.with_recovery`); returns ``(result, facts)``:
        the left image, the initial foreground (left view) and the initialisation's report
        of the run kept.  A pair that :meth:`locate` set up runs from that set-up.
        ``anchor``: a left-view :class:`~lss_kernels.start_types.Point` the object must hold
        (:func:`~lss_kernels.checks.recovery.with_recovery`; None: none)."""
        from .checks.pair import CheckedPair
        from .checks.recovery import with_recovery
        pair = self._primed_pair(left, init, init_frame)
        if pair is None:
            pair = CheckedPair(left, right, d_max, init, init_frame, params)

        def run(p):
            result, solver = self._run(pair, p, callback)
            return result, (solver.left_image, solver.initial_left, solver.init_info)
        return with_recovery(run, params, pair.d_max, pair, anchor)

    def locate(self, left, right, d_max, start, params):
        """The initial foreground (left view) that a solve of the pair with ``params``
        would start from (``start`` in the left view), kept set up for :meth:`solve_pair`
        of the same pair and start.  A periodic pair's first run changes the parameters
        (:func:`~lss_kernels.checks.recovery.with_recovery`) and sets up again."""
        from .checks.pair import CheckedPair
        pair = CheckedPair(left, right, d_max, start, "left", params)
        self._set_up(pair, params)
        self.primed = (pair, start, left)
        return self.solver.initial_left

    def forget(self):
        """Drop a located set-up that no solve used (the solver stays for reuse)."""
        self.primed = None

    def _primed_pair(self, left, init, init_frame):
        """The pair :meth:`locate` set up for this crop and start, or None."""
        if self.primed is None:
            return None
        pair, start, located = self.primed
        if (init_frame == "left" and type(init) is type(start) and start == init
                and np.shape(left) == located.shape
                and np.array_equal(left, located)):
            return pair
        return None

    def _set_up(self, pair, params):
        """This cache's solver for ``pair``, set up (reused when the size, search range and
        parameters are its own, else new)."""
        from .solver import Solver
        key = _key(pair, params)
        args = (pair, pair.right, pair.d_max, pair.init)
        self.primed = None
        if key == self.key:
            self.solver.reset(*args, init_frame=pair.init_frame)
        else:
            self.close()
            self.solver = Solver(*args, params=params, init_frame=pair.init_frame)
            self.key = key

    def _run(self, pair, params, callback=None):
        """Solve a :class:`~lss_kernels.checks.pair.CheckedPair` with a reused or new
        solver (as :meth:`locate` set it up, when it did); returns ``(result, solver)``."""
        primed = self.primed is not None and self.primed[0] is pair
        if not (primed and self.key == _key(pair, params)):
            self._set_up(pair, params)
        self.primed = None
        return self.solver.run(callback), self.solver

    def close(self):
        if self.solver is not None:
            self.solver.close()
        self.key, self.solver, self.primed = None, None, None


def _key(pair, params) -> tuple:
    """What a solver must share with ``pair`` to be reset for it instead of built anew:
    the image size, the candidate count of the search range and the parameters."""
    return (pair.left.shape[:2], c_max(pair.d_max), params)
