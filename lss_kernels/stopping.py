"""The stopping rule of the alternation, and its replay over a recorded run.

The paper (and the authors' release) runs a fixed number of iterations.  The solver stops
earlier once the foreground has settled: every ``stop_window`` iterations it counts the pixels
whose label differs from ``stop_window`` iterations before (the net change: a boundary that
oscillates does not count) and divides them by the boundary's length in pixels, the mean
distance the boundary has moved over the window (its *shift*); the window is quiet when that
is below ``stop_shift`` pixels and neither layer's surface moved by ``stop_surface`` pixels
or more between two re-initialisations within it (surfaces that still cycle under a settled
boundary), unless no pixel changed its label at all (surfaces that cycle under a boundary
that stands still cannot move it).  It stops after ``stop_patience`` quiet windows in a row,
not before ``min_iterations`` (see :class:`lss_kernels.Params`).

:func:`replay` applies the rule, or a variant of it, to the per-window record of a finished
run (``lss eval --trace``): how many iterations another rule would have taken, and at what
accuracy.  Taichi-free.
"""
__all__ = ["StopRule", "format_shift", "replay"]


class StopRule:
    """The convergence part of the rule (the iteration cap and a vanished or full foreground
    are the solver's own stops).

    Parameters
    ----------
    params : lss_kernels.Params
        ``stop_window``, ``stop_shift``, ``stop_surface``, ``stop_patience``,
        ``min_iterations``.
    """

    def __init__(self, params):
        self.window = int(params.stop_window)
        self.shift = float(params.stop_shift)
        self.surface = float(params.stop_surface)
        self.patience = int(params.stop_patience)
        self.min_iterations = int(params.min_iterations)
        self.quiet = 0          # consecutive quiet windows

    def is_window_end(self, iteration: int) -> bool:
        return iteration % self.window == 0

    def record(self, boundary_shift: float, surface_change: float) -> None:
        """The window that just ended: the boundary's mean shift over it (changed pixels over
        boundary pixels) and the largest move of a layer's surface between two
        re-initialisations within it (left-view pixels; 0 when none fell within it)."""
        # a boundary that did not move at all is settled whatever its surfaces do: surfaces
        # that cycle under it will not move it (a limit cycle, waited for to the cap)
        settled = self.surface <= 0 or surface_change < self.surface or boundary_shift == 0
        self.quiet = self.quiet + 1 if boundary_shift < self.shift and settled else 0

    def converged(self, iteration: int) -> bool:
        """Whether to stop after ``iteration`` (windows before ``min_iterations`` count towards
        the patience, so the rule can fire at ``min_iterations``)."""
        return (self.shift > 0 and iteration >= self.min_iterations
                and self.is_window_end(iteration) and self.quiet >= self.patience)


def format_shift(shift) -> str:
    """A progress line's boundary shift: ``0.042 px``, or ``-`` before the first window."""
    return "-" if shift is None else f"{shift:.3f} px"


def replay(windows, params, **changes):
    """Where the stopping rule of ``params`` (with ``changes`` applied, e.g.
    ``stop_shift=0.2``) stops on a recorded run.

    Parameters
    ----------
    windows : sequence of dict
        The run's record at the end of each stop window, in order: ``iteration``,
        ``boundary_shift`` and ``surface_change`` (any other keys are passed through), plus
        possibly a last entry at the run's final iteration.
    params : lss_kernels.Params
        The parameters of the recorded run (its ``stop_window`` must be the one recorded).

    Returns
    -------
    (dict, bool)
        The entry at which the rule stops, and whether it stopped there by the rule (False:
        the record ended first, and the rule would have run at least that long).
    """
    params = params.replace(**changes)
    rule = StopRule(params)
    entry = None
    for entry in windows:
        it = int(entry["iteration"])
        if rule.is_window_end(it):
            rule.record(float(entry["boundary_shift"]), float(entry["surface_change"]))
        if rule.converged(it) or it >= params.max_iterations:
            return entry, True
    if entry is None:
        raise ValueError("replay: windows is empty")
    return entry, False
