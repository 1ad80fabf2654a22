"""The whole solver on rendered two-layer scenes with exact ground truth."""
import numpy as np
import pytest

from lss_kernels import Params, Solver, solve
from lss_kernels.metrics import score
from lss_kernels.scenes import make_scene


@pytest.fixture(scope="module")
def easy(ti_arch):
    scene = make_scene("easy")
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    return scene, result


def test_recovers_the_boundary_of_an_easy_scene(easy):
    scene, result = easy
    s = score(result.disparity, result.occlusion, scene)
    assert s["occ_f1"] >= 0.9
    assert s["bad4"] <= 5.0
    iou = (result.foreground & scene.fg_left).sum() / (result.foreground | scene.fg_left).sum()
    assert iou >= 0.95
    # Theta in left-view disparity: the planes at 24 and 8 pixels
    assert result.theta_fg[5] + result.theta_fg[3] * 60 == pytest.approx(24.0, abs=0.5)
    assert result.theta_bg[5] == pytest.approx(8.0, abs=0.5)


def test_result_maps_are_finite_and_consistent(easy):
    scene, result = easy
    H, W = scene.left.shape[:2]
    for name in ("disparity", "phi", "consensus_mean", "consensus_sigma"):
        a = getattr(result, name)
        assert a.shape == (H, W) and np.isfinite(a).all(), name
    assert result.occlusion.dtype == bool and result.foreground.dtype == bool
    assert not (result.occlusion & result.foreground).any()
    assert (result.disparity >= 0).all()
    assert result.iterations == len(result.history) >= 1
    assert result.stop_reason.startswith("converged")
    assert result.timings["total"] > 0


@pytest.mark.slow
def test_stepping_gives_the_same_result_as_solve(easy):
    scene, result = easy
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse)
    while not solver.done:
        solver.step()
    stepped = solver.result()
    solver.close()
    assert stepped.iterations == result.iterations
    np.testing.assert_array_equal(stepped.disparity, result.disparity)
    np.testing.assert_array_equal(stepped.phi, result.phi)


@pytest.mark.slow
def test_recovers_a_slanted_curved_scene(ti_arch):
    scene = make_scene("slanted")
    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse_cyclopean,
                   init_frame="cyclopean")
    s = score(result.disparity, result.occlusion, scene)
    assert s["occ_f1"] >= 0.85
    assert s["bad4"] <= 10.0


@pytest.mark.slow
def test_callback_sees_every_iteration_and_can_stop(ti_arch):
    scene = make_scene("easy")
    seen = []

    def callback(solver, stats):
        seen.append(stats["iteration"])
        return stats["iteration"] < 7

    result = solve(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                   params=Params(max_iterations=50), callback=callback)
    assert seen == list(range(1, 8))
    assert result.iterations == 7 and "callback" in result.stop_reason


@pytest.mark.slow
def test_memory_stays_within_the_volume_budget(ti_arch):
    scene = make_scene("easy")
    solver = Solver(scene.left, scene.right, scene.d_max, scene.init_ellipse,
                    params=Params(max_iterations=1))
    H, W = scene.left.shape[:2]
    levels = len(solver.params.patch_sizes)
    budget = 4 * H * W * solver.c_max * (levels + 2)
    # the intermediate levels carry margins of patch centres outside the image
    m = [lev.margin for lev in solver.hierarchy.levels]
    margins = sum(4 * ((H + 2 * k) * (W + 2 * k) - H * W) * solver.c_max for k in m)
    assert solver.memory_bytes <= budget + margins + 64 * H * W * 4
    solver.close()
