"""The stopping rule (lss_kernels.stopping): hand-made records, and the solver's own stop
replayed from its history."""
import pytest

from lss_kernels.params import Params
from lss_kernels.stopping import StopRule, replay

P = Params(stop_window=10, stop_shift=0.01, stop_patience=2, min_iterations=30,
           max_iterations=100)


def _windows(moving, window=10, surfaces=None):
    surfaces = surfaces or [0.0] * len(moving)
    return [{"iteration": window * (i + 1), "boundary_shift": m, "surface_change": s, "tag": i}
            for i, (m, s) in enumerate(zip(moving, surfaces))]


def test_rule_needs_patience_quiet_windows_in_a_row():
    rule = StopRule(P)
    fired = []
    for entry in _windows([0.5, 0.001, 0.5, 0.001, 0.002, 0.001]):
        rule.record(entry["boundary_shift"], entry["surface_change"])
        fired.append(rule.converged(entry["iteration"]))
    # quiet counts: 0, 1, 0, 1, 2, 3 -> the first stop at the fifth window (iteration 50)
    assert fired == [False, False, False, False, True, True]


def test_quiet_windows_before_min_iterations_count_towards_patience():
    entry, fired = replay(_windows([0.001, 0.001, 0.001, 0.5]), P)
    assert fired and entry["iteration"] == 30        # min_iterations, not 20
    entry, fired = replay(_windows([0.001, 0.001, 0.001]), P, min_iterations=15)
    assert fired and entry["iteration"] == 20


def test_rule_never_fires_off_a_window_end_or_when_disabled():
    rule = StopRule(P)
    rule.record(0.0, 0.0)
    rule.record(0.0, 0.0)
    assert rule.converged(40) and not rule.converged(41)
    off = StopRule(Params(stop_shift=0.0))
    off.record(0.0, 0.0)
    off.record(0.0, 0.0)
    assert not off.converged(off.min_iterations)


def test_a_window_whose_surfaces_moved_is_not_quiet():
    """A settled boundary over a model that still moves (``surface_change`` at or above
    ``stop_surface``) does not count; ``stop_surface = 0`` leaves the surfaces out."""
    windows = _windows([0.001] * 5, surfaces=[0.0, 2.0, 1.0, 0.5, 0.5])   # P: 1.0 px
    assert replay(windows, P) == (windows[4], True)      # quiet: windows 0, 3, 4
    assert replay(windows, P, stop_surface=0.0) == (windows[2], True)  # min_iterations 30
    assert replay(windows, P, stop_surface=2.5) == (windows[2], True)


def test_surfaces_that_cycle_under_a_boundary_that_stands_still_do_not_hold_the_rule():
    """No pixel changed its label (shift 0): the surfaces' cycle cannot move the boundary,
    so the window is quiet whatever they do; a boundary that moves at all keeps the test."""
    windows = _windows([0.001, 0.0, 0.0, 0.001, 0.0], surfaces=[2.0, 2.04, 2.04, 2.04, 2.04])
    assert replay(windows, P) == (windows[2], True)      # quiet: windows 1, 2 (at 30)
    moving = _windows([0.001] * 5, surfaces=[2.04] * 5)
    assert replay(moving, P) == (moving[4], False)       # never quiet: the record ends


def test_replay_variants_and_the_end_of_the_record():
    windows = _windows([0.5, 0.02, 0.02, 0.005, 0.005, 0.002])
    assert replay(windows, P) == (windows[4], True)                     # 0.01: windows 4, 5
    assert replay(windows, P, stop_shift=0.03) == (windows[2], True)  # from window 2
    assert replay(windows, P, stop_shift=0.001) == (windows[-1], False)
    assert replay(windows, P, max_iterations=20) == (windows[1], True)
    with pytest.raises(ValueError, match="empty"):
        replay([], P)


@pytest.mark.slow
def test_replay_of_a_solver_history_gives_its_stop(ti_arch):
    from lss_kernels.scenes import make_scene
    from lss_kernels.solver import Solver
    scene = make_scene("easy")
    params = Params(min_iterations=20, stop_window=10, stop_shift=0.5, stop_surface=2.0,
                    stop_patience=2)
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse, params=params)
    result = solver.run()
    solver.close()
    assert result.stop_reason.startswith("converged")
    windows = [h for h in result.history if h["iteration"] % params.stop_window == 0]
    entry, fired = replay(windows, params)
    assert fired and entry["iteration"] == result.iterations
    # a stricter rule would have run longer: the record ends first
    assert replay(windows, params, stop_shift=params.stop_shift / 1e6)[1] is False
