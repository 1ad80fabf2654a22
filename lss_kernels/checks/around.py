"""``solve``: the checks wrapped around a :class:`~lss_kernels.Solver`."""
from ..solver import Solver
from .pair import CheckedPair
from .recovery import with_recovery
from .validate import check_params

__all__ = ["solve"]


def solve(left, right, d_max, init, params=None, arch=None, callback=None, init_frame="left",
          profile=False):
    """Solve a rectified pair with the two-layer level-set model (the whole paper).

    Arguments as for :class:`~lss_kernels.Solver`, and ``callback``: ``callback(solver,
    stats)`` after every iteration; return ``False`` to stop.  The pair is checked once
    (:class:`~lss_kernels.checks.pair.CheckedPair`); swapped views and a search range too
    short warn before the solve, and a collapsed model is solved again
    (:func:`~lss_kernels.checks.recovery.with_recovery`).

    Returns
    -------
    Result
        Left-view disparity, occlusion and foreground; the model (phi, Theta) and the
        consensus in the cyclopean frame.

    References
    ----------
    J. Wang and T. Zickler, "Level Set Stereo for Cooperative Grouping with Occlusion".
    """
    params = check_params(params)
    pair = CheckedPair(left, right, d_max, init, init_frame, params)

    def run(p):
        solver = Solver(pair, pair.right, pair.d_max, pair.init, params=p, arch=arch,
                        init_frame=init_frame, profile=profile)
        try:
            return solver.run(callback), None
        finally:
            solver.close()
    return with_recovery(run, params, pair.d_max, pair)[0]
